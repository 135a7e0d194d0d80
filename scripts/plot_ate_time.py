#!/usr/bin/python3
"""Plot the merged and the odometry error over time, per agent.

Usage:
  plot_ate_time.py --csv ate_over_time.csv --out ate_over_time.png [--title TEXT]

CSV (written by hermes_run): header `time_s,agent,kind,error_m`; time_s [s] on the
run's simulated clock (0 = the agent's first frame); kind `merged`: the position
error of a merged keyframe under the run's one common alignment (solid line),
`odometry`: the position error of the agent's own odometry aligned on its own
(dashed line, same colour), `global`: the robot's own idea of its place in the
world at each frame (the server's latest world <- odom times its odometry), under
the common alignment (dotted line). Where the solid line is above the dashed one,
the merge made that agent worse than its odometry. Exit code 2 with a one-line reason
on bad input.
"""
import argparse
import csv
import sys


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--csv", required=True, help="ate_over_time.csv")
    ap.add_argument("--out", required=True, help="output PNG")
    ap.add_argument("--title", default="Error over time: merged (solid) vs own odometry (dashed)")
    a = ap.parse_args()
    series = {}
    try:
        with open(a.csv, newline="") as f:
            rows = csv.reader(f)
            header = next(rows, None)
            if header != ["time_s", "agent", "kind", "error_m"]:
                raise ValueError(f"{a.csv}: header must be time_s,agent,kind,error_m, got {header}")
            for n, row in enumerate(rows, start=2):
                if len(row) != 4:
                    raise ValueError(f"{a.csv}:{n}: expected 4 columns, got {len(row)}")
                if row[2] not in ("merged", "odometry", "global"):
                    raise ValueError(f"{a.csv}:{n}: kind must be merged, odometry or global, got {row[2]}")
                t, name, e = float(row[0]), row[1], float(row[3])
                series.setdefault(name, {}).setdefault(row[2], []).append((t, e))
    except (OSError, ValueError) as e:
        print(f"plot_ate_time.py: {e}", file=sys.stderr)
        return 2
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(8, 4))
    for i, (name, kinds) in enumerate(sorted(series.items())):
        colour = f"C{i % 10}"
        for kind, style in (("merged", "-"), ("odometry", "--"), ("global", ":")):
            pts = sorted(kinds.get(kind, []))
            if pts:
                ax.plot([p[0] for p in pts], [100.0 * p[1] for p in pts], style, color=colour,
                        marker="." if kind == "merged" else None, markersize=3,
                        label=f"{name} {kind}")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("position error [cm]")
    ax.set_title(a.title)
    ax.grid(True, alpha=0.3)
    if series:
        ax.legend(fontsize=7)
    else:
        ax.text(0.5, 0.5, "no agent with ground truth", ha="center", transform=ax.transAxes)
    fig.tight_layout()
    fig.savefig(a.out, dpi=110)
    return 0


if __name__ == "__main__":
    sys.exit(main())
