#!/usr/bin/python3
"""Plot the last pose-graph solve's edge residuals over time, one panel per agent.

Usage:
  plot_pose_graph.py --csv pose_graph_edges.csv --out pose_graph.png [--title TEXT]

CSV (written by hermes_run): header `kind,agent_a,keyframe_a,agent_b,keyframe_b,
stamp_a,stamp_b,residual_m,residual_deg,chi2,weight,loop_error_m`. Each agent's
panel shows its odometry edges' residual [cm] at their start time (grey line) and
the loops touching it (dots at its keyframe's time: blue while the solve
trusts them, weight >= 0.1; red where the robust loss gave them up, weight < 0.1,
i.e. chi2 above 9x the loss scale squared). Odometry edges far above
their neighbours are where the graph broke the odometry; red loops are where it
kept the odometry against the loops. Exit code 2 with a one-line reason on bad input.
"""
import argparse
import csv
import sys

HEADER = ["kind", "agent_a", "keyframe_a", "agent_b", "keyframe_b", "stamp_a", "stamp_b",
          "residual_m", "residual_deg", "chi2", "weight", "loop_error_m"]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--csv", required=True, help="pose_graph_edges.csv")
    ap.add_argument("--out", required=True, help="output PNG")
    ap.add_argument("--title", default="Pose graph residuals after the last solve")
    a = ap.parse_args()
    odo, loops = {}, {}
    try:
        with open(a.csv, newline="") as f:
            rows = csv.reader(f)
            header = next(rows, None)
            if header != HEADER:
                raise ValueError(f"{a.csv}: header must be {','.join(HEADER)}, got {header}")
            for n, row in enumerate(rows, start=2):
                if len(row) != len(HEADER):
                    raise ValueError(f"{a.csv}:{n}: expected {len(HEADER)} columns, got {len(row)}")
                kind, ag_a, ag_b = row[0], row[1], row[3]
                ta, tb, res, w = float(row[5]), float(row[6]), float(row[7]), float(row[10])
                if kind == "odometry":
                    odo.setdefault(ag_a, []).append((ta, res))
                elif kind == "loop":
                    loops.setdefault(ag_a, []).append((ta, res, w))
                    if ag_b != ag_a:
                        loops.setdefault(ag_b, []).append((tb, res, w))
                else:
                    raise ValueError(f"{a.csv}:{n}: kind must be odometry or loop, got {kind}")
    except (OSError, ValueError) as e:
        print(f"plot_pose_graph.py: {e}", file=sys.stderr)
        return 2
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    agents = sorted(set(odo) | set(loops))
    fig, axes = plt.subplots(max(1, len(agents)), 1, figsize=(8, 1.8 + 1.6 * max(1, len(agents))),
                             sharex=True, squeeze=False)
    for ax, name in zip(axes[:, 0], agents):
        pts = sorted(odo.get(name, []))
        if pts:
            ax.plot([p[0] for p in pts], [100 * p[1] for p in pts], color="0.5", lw=1, label="odometry edge")
        for trusted, colour, label in ((True, "C0", "loop (trusted)"), (False, "C3", "loop (given up)")):
            sel = [p for p in loops.get(name, []) if (p[2] >= 0.1) == trusted]
            if sel:
                ax.scatter([p[0] for p in sel], [100 * p[1] for p in sel], s=6, color=colour, label=label)
        ax.set_ylabel(f"{name}\nresidual [cm]", fontsize=8)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=6, loc="upper right")
    if not agents:
        axes[0, 0].text(0.5, 0.5, "no pose graph solved", ha="center", transform=axes[0, 0].transAxes)
    axes[-1, 0].set_xlabel("time [s]")
    axes[0, 0].set_title(a.title)
    fig.tight_layout()
    fig.savefig(a.out, dpi=110)
    return 0


if __name__ == "__main__":
    sys.exit(main())
