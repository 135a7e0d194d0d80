#!/usr/bin/python3
"""Plot the merged trajectory error over time, one line per agent.

Usage:
  plot_ate_time.py --csv ate_over_time.csv --out ate_over_time.png [--title TEXT]

CSV (written by hermes_run): header `time_s,agent,error_m`; time_s [s] on the run's
simulated clock (0 = the agent's first frame), error_m [m] the position error of a
merged keyframe under the run's one common alignment. Exit code 2 with a one-line
reason on bad input.
"""
import argparse
import csv
import sys


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--csv", required=True, help="ate_over_time.csv")
    ap.add_argument("--out", required=True, help="output PNG")
    ap.add_argument("--title", default="Merged trajectory error over time")
    a = ap.parse_args()
    series = {}
    try:
        with open(a.csv, newline="") as f:
            rows = csv.reader(f)
            header = next(rows, None)
            if header != ["time_s", "agent", "error_m"]:
                raise ValueError(f"{a.csv}: header must be time_s,agent,error_m, got {header}")
            for n, row in enumerate(rows, start=2):
                if len(row) != 3:
                    raise ValueError(f"{a.csv}:{n}: expected 3 columns, got {len(row)}")
                t, name, e = float(row[0]), row[1], float(row[2])
                series.setdefault(name, []).append((t, e))
    except (OSError, ValueError) as e:
        print(f"plot_ate_time.py: {e}", file=sys.stderr)
        return 2
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(8, 4))
    for name, pts in sorted(series.items()):
        pts.sort()
        ax.plot([p[0] for p in pts], [100.0 * p[1] for p in pts], marker=".", label=name)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("position error [cm]")
    ax.set_title(a.title)
    ax.grid(True, alpha=0.3)
    if series:
        ax.legend()
    else:
        ax.text(0.5, 0.5, "no merged agent", ha="center", transform=ax.transAxes)
    fig.tight_layout()
    fig.savefig(a.out, dpi=110)
    return 0


if __name__ == "__main__":
    sys.exit(main())
