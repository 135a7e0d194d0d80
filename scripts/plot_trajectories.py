#!/usr/bin/python3
"""Top view (x-y) of estimated trajectories against ground truth, one colour per agent.

Usage:
  plot_trajectories.py --gt GT --est EST [--gt GT2 --est EST2 ...] --out PLOT.png
                       [--align merged|per-agent|none] [--metrics metrics.json]
                       [--max-dt S] [--title TEXT]

GT / EST are TUM files (`t tx ty tz qx qy qz qw`, '#' comments) or EuRoC ground-truth
csv files (`ns, px, py, pz, qw, qx, qy, qz, ...`, detected by a nanosecond first
column or a `p_RS_R_x` header). --gt/--est pair up in order, one pair per agent.

Alignment of the estimates into the ground-truth frame (positions only):
  merged     (default) ONE SE(3) Umeyama transform for all agents together, like the
             merged ATE of hermes_eval: an agent whose map is offset stays visibly off;
  per-agent  one SE(3) Umeyama transform per agent;
  none       plot the estimates as they are.
--metrics FILE uses the transform stored by hermes_eval (`alignment.t_xyz`,
`alignment.q_xyzw`, `alignment.scale`) for all agents instead of computing one.

Estimates are matched to ground truth by linear interpolation at their stamps; poses
farther than --max-dt (default 0.02 s) from every gt sample are not used for the
alignment (they are still drawn). Exit code 2 with a one-line reason on bad input.
"""
import argparse
import json
import os
import sys

import numpy as np


def die(msg):
    print("plot_trajectories: " + msg, file=sys.stderr)
    sys.exit(2)


def read_trajectory(path):
    """Returns (t [s], positions Nx3) of a TUM file or a EuRoC ground-truth csv."""
    if os.path.isdir(path):
        for rel in ("mav0/state_groundtruth_estimate0/data.csv",
                    "state_groundtruth_estimate0/data.csv"):
            if os.path.isfile(os.path.join(path, rel)):
                path = os.path.join(path, rel)
                break
        else:
            die("folder '%s' holds no EuRoC ground truth" % path)
    if not os.path.isfile(path):
        die("trajectory '%s' does not exist" % path)
    rows, euroc = [], None
    with open(path) as f:
        for lineno, line in enumerate(f, 1):
            s = line.strip()
            if not s:
                continue
            if s.startswith("#"):
                if "p_RS_R_x" in s:
                    euroc = True
                continue
            parts = s.replace(",", " ").split()
            if euroc is None:
                euroc = parts[0].isdigit() and len(parts[0]) >= 13
            try:
                vals = [float(v) for v in parts[:8]]
            except ValueError:
                die("%s:%d: not a number" % (path, lineno))
            if len(vals) < 8:
                die("%s:%d: expected 8 columns" % (path, lineno))
            if euroc:
                vals[0] = int(parts[0]) * 1e-9
            rows.append(vals[:4])
    if not rows:
        die("trajectory '%s' holds no poses" % path)
    a = np.asarray(rows)
    order = np.argsort(a[:, 0], kind="stable")
    return a[order, 0], a[order, 1:4]


def associate(t_gt, p_gt, t_est, max_dt):
    """Indices of matched estimates and the interpolated gt positions."""
    idx = np.searchsorted(t_gt, t_est)
    lo = np.clip(idx - 1, 0, len(t_gt) - 1)
    hi = np.clip(idx, 0, len(t_gt) - 1)
    nearest = np.minimum(np.abs(t_est - t_gt[lo]), np.abs(t_gt[hi] - t_est))
    ok = nearest <= max_dt
    p = np.column_stack([np.interp(t_est, t_gt, p_gt[:, k]) for k in range(3)])
    return np.nonzero(ok)[0], p[ok]


def umeyama_se3(src, dst):
    """R, t minimising sum |dst - (R src + t)|^2."""
    if len(src) < 3:
        die("alignment needs at least 3 matched poses, got %d" % len(src))
    mu_s, mu_d = src.mean(0), dst.mean(0)
    cov = (dst - mu_d).T @ (src - mu_s) / len(src)
    u, _, vt = np.linalg.svd(cov)
    s = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        s[2, 2] = -1
    r = u @ s @ vt
    return r, mu_d - r @ mu_s


def quat_to_rot(qx, qy, qz, qw):
    q = np.array([qw, qx, qy, qz], float)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def transform_from_metrics(path):
    try:
        with open(path) as f:
            m = json.load(f)
    except (OSError, ValueError) as e:
        die("cannot read metrics '%s': %s" % (path, e))
    a = m.get("alignment") if isinstance(m, dict) else None
    if not isinstance(a, dict) or "t_xyz" not in a or "q_xyzw" not in a:
        die("metrics '%s' has no field 'alignment.t_xyz'/'alignment.q_xyzw'" % path)
    return float(a.get("scale", 1.0)) * quat_to_rot(*a["q_xyzw"]), np.asarray(a["t_xyz"], float)


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--gt", action="append", default=[], help="ground truth (repeatable)")
    ap.add_argument("--est", action="append", default=[], help="estimate (repeatable)")
    ap.add_argument("--name", action="append", default=[], help="agent names, in order")
    ap.add_argument("--out", required=True, help="output PNG")
    ap.add_argument("--align", choices=["merged", "per-agent", "none"], default="merged")
    ap.add_argument("--metrics", help="metrics JSON whose alignment transform to use")
    ap.add_argument("--max-dt", type=float, default=0.02, help="[s] association window")
    ap.add_argument("--title", default=None)
    args = ap.parse_args()
    if not args.gt or len(args.gt) != len(args.est):
        die("needs matching --gt/--est pairs (got %d --gt, %d --est)"
            % (len(args.gt), len(args.est)))
    if args.name and len(args.name) != len(args.est):
        die("give one --name per --est or none")

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    agents = []
    for k, (g, e) in enumerate(zip(args.gt, args.est)):
        t_gt, p_gt = read_trajectory(g)
        t_est, p_est = read_trajectory(e)
        idx, p_match = associate(t_gt, p_gt, t_est, args.max_dt)
        name = args.name[k] if args.name else os.path.splitext(os.path.basename(e.rstrip("/")))[0]
        agents.append(dict(name=name, p_gt=p_gt, p_est=p_est, idx=idx, p_match=p_match))
        if len(idx) == 0:
            die("%s: no estimate pose has ground truth within %g s" % (name, args.max_dt))

    if args.metrics:
        r, t = transform_from_metrics(args.metrics)
        transforms = [(r, t)] * len(agents)
    elif args.align == "merged":
        src = np.vstack([a["p_est"][a["idx"]] for a in agents])
        dst = np.vstack([a["p_match"] for a in agents])
        transforms = [umeyama_se3(src, dst)] * len(agents)
    elif args.align == "per-agent":
        transforms = [umeyama_se3(a["p_est"][a["idx"]], a["p_match"]) for a in agents]
    else:
        transforms = [(np.eye(3), np.zeros(3))] * len(agents)

    fig, ax = plt.subplots(figsize=(8, 7))
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for k, (a, (r, t)) in enumerate(zip(agents, transforms)):
        c = colors[k % len(colors)]
        p = a["p_est"] @ r.T + t
        err = np.linalg.norm(p[a["idx"]] - a["p_match"], axis=1)
        rmse = float(np.sqrt(np.mean(err ** 2)))
        ax.plot(a["p_gt"][:, 0], a["p_gt"][:, 1], "--", color=c, lw=1, alpha=0.6,
                label="%s ground truth" % a["name"])
        ax.plot(p[:, 0], p[:, 1], "-", color=c, lw=1.5,
                label="%s estimate (ATE %.3f m)" % (a["name"], rmse))
        ax.plot(p[0, 0], p[0, 1], "o", color=c, ms=5)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    mode = "metrics JSON transform" if args.metrics else {"merged": "one common SE(3) alignment",
                                                          "per-agent": "per-agent SE(3) alignment",
                                                          "none": "no alignment"}[args.align]
    ax.set_title(args.title or "Top view, %s" % mode)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    try:
        fig.savefig(args.out, dpi=120)
    except OSError as e:
        print("plot_trajectories: cannot write '%s': %s" % (args.out, e), file=sys.stderr)
        sys.exit(1)
    print("wrote " + args.out, file=sys.stderr)


if __name__ == "__main__":
    main()
