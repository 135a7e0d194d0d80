#!/usr/bin/python3
"""Fit the odometry noise model (config `odometry.*`) to odometry against ground truth.

Usage:
  fit_odometry_noise.py RUN_DIR [RUN_DIR ...] [--spans 0.3,1,3,10] [--json OUT]

Reads every RUN_DIR/trajectories/<agent>_raw.tum with its <agent>_gt.tum (written
by `./hermes run`). For pairs of odometry poses (i, j) whose ground-truth path
between them is about d metres long (d in --spans), the relative pose error
E = (G_i^-1 G_j)^-1 (O_i^-1 O_j) is taken; its per-axis translation variance
|t_E|^2 / 3 and rotation variance angle(E)^2 / 3 are regressed on the distance d
and the turned angle theta of the pair as the model does:
  var_t = trans_floor_m^2 + trans_per_sqrt_m^2 d + trans_per_sqrt_rad^2 theta
  var_r = rot_floor_rad^2 + rot_per_sqrt_m^2   d + rot_per_sqrt_rad^2   theta
(non-negative least squares). Prints the fitted keys as JSON (and writes them to
--json); exit code 2 with a one-line reason on bad input.
"""
import argparse
import glob
import json
import os
import sys

import numpy as np


def quat_to_R(q):
    x, y, z, w = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def load_tum(path):
    d = np.loadtxt(path, ndmin=2)
    if d.shape[1] != 8:
        raise ValueError(f"{path}: expected 8 columns (TUM), got {d.shape[1]}")
    return d


def poses(d):
    return [(quat_to_R(r[4:8]), r[1:4]) for r in d]


def angle(R):
    return float(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1)))


def samples(raw_path, gt_path, spans):
    raw, gt = load_tum(raw_path), load_tum(gt_path)
    # Ground truth at the odometry stamps (nearest sample within 20 ms).
    idx = np.searchsorted(gt[:, 0], raw[:, 0]).clip(1, len(gt) - 1)
    near = np.where(np.abs(gt[idx - 1, 0] - raw[:, 0]) < np.abs(gt[idx, 0] - raw[:, 0]), idx - 1, idx)
    ok = np.abs(gt[near, 0] - raw[:, 0]) < 0.02
    raw, g = raw[ok], gt[near[ok]]
    if len(raw) < 10:
        return []
    O, G = poses(raw), poses(g)
    path = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(g[:, 1:4], axis=0), axis=1))])
    out = []
    for d in spans:
        j = np.searchsorted(path, path + d)
        for i in range(0, len(raw), 3):
            if j[i] >= len(raw):
                break
            Rg = G[i][0].T @ G[j[i]][0]
            tg = G[i][0].T @ (G[j[i]][1] - G[i][1])
            Ro = O[i][0].T @ O[j[i]][0]
            to = O[i][0].T @ (O[j[i]][1] - O[i][1])
            Re = Rg.T @ Ro
            te = Rg.T @ (to - tg)
            out.append((path[j[i]] - path[i], angle(Rg), float(te @ te) / 3, angle(Re) ** 2 / 3))
    return out


def nnls(A, b):
    """Non-negative least squares by active-set elimination (few unknowns)."""
    free = list(range(A.shape[1]))
    while True:
        x = np.zeros(A.shape[1])
        x[free] = np.linalg.lstsq(A[:, free], b, rcond=None)[0]
        neg = [k for k in free if x[k] < 0]
        if not neg:
            return x
        free.remove(min(neg, key=lambda k: x[k]))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", help="results folders of ./hermes run")
    ap.add_argument("--spans", default="0.3,1,3,10", help="path lengths d [m], comma-separated")
    ap.add_argument("--json", help="write the fitted keys here")
    a = ap.parse_args()
    try:
        spans = [float(s) for s in a.spans.split(",")]
        rows = []
        for run in a.runs:
            raws = glob.glob(os.path.join(run, "trajectories", "*_raw.tum"))
            if not raws:
                raise ValueError(f"{run}: no trajectories/*_raw.tum")
            for raw in raws:
                gt = raw[: -len("_raw.tum")] + "_gt.tum"
                if os.path.exists(gt):
                    rows += samples(raw, gt, spans)
        if len(rows) < 20:
            raise ValueError("too few odometry pairs with ground truth")
    except (OSError, ValueError) as e:
        print(f"fit_odometry_noise.py: {e}", file=sys.stderr)
        return 2
    r = np.array(rows)
    A = np.column_stack([np.ones(len(r)), r[:, 0], r[:, 1]])
    xt, xr = nnls(A, r[:, 2]), nnls(A, r[:, 3])
    fit = {"odometry.trans_floor_m": float(np.sqrt(xt[0])), "odometry.trans_per_sqrt_m": float(np.sqrt(xt[1])),
           "odometry.trans_per_sqrt_rad": float(np.sqrt(xt[2])), "odometry.rot_floor_rad": float(np.sqrt(xr[0])),
           "odometry.rot_per_sqrt_m": float(np.sqrt(xr[1])), "odometry.rot_per_sqrt_rad": float(np.sqrt(xr[2])),
           "pairs": len(r)}
    # Observed sigma per span next to the model's, to judge the fit.
    fit["per_span"] = []
    for d in spans:
        m = np.abs(r[:, 0] - d) < 0.25 * d
        if m.any():
            th = float(r[m, 1].mean())
            fit["per_span"].append({"d_m": d, "sigma_t_m": float(np.sqrt(r[m, 2].mean())),
                                    "model_t_m": float(np.sqrt(xt @ [1, d, th])),
                                    "sigma_r_rad": float(np.sqrt(r[m, 3].mean())),
                                    "model_r_rad": float(np.sqrt(xr @ [1, d, th]))})
    text = json.dumps(fit, indent=2)
    print(text)
    if a.json:
        with open(a.json, "w") as f:
            f.write(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
