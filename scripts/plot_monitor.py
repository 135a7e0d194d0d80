#!/usr/bin/python3
"""Plot the bandwidth monitor's estimate against the link's true rate.

Usage:
  plot_monitor.py --csv monitor_curve.csv --out monitor_curve.png [--title TEXT]

CSV (written by hermes_bench_monitor; one header line):
  time_s,true_mbitps,estimate_mbitps,outage
  time_s           [s] simulated time
  true_mbitps      [Mbit/s] rate of the emulated link at time_s (0 = outage)
  estimate_mbitps  [Mbit/s] the monitor's estimate at time_s
  outage           1 when the monitor reports an outage, else 0

The true rate is a black step line, the estimate blue, the +-20 % band around the
true rate light grey, true outages shaded red and detected outages marked on the
time axis. Exit code 2 with a one-line reason on bad input.
"""
import argparse
import csv
import sys


def die(msg):
    print("plot_monitor: " + msg, file=sys.stderr)
    sys.exit(2)


def read(path):
    cols = ("time_s", "true_mbitps", "estimate_mbitps", "outage")
    try:
        with open(path, newline="") as f:
            rows = list(csv.DictReader(f))
    except OSError as e:
        die("cannot read %s: %s" % (path, e.strerror))
    if not rows:
        die("%s: no data rows" % path)
    missing = [c for c in cols if c not in rows[0]]
    if missing:
        die("%s: missing column(s) %s" % (path, ", ".join(missing)))
    out = {c: [] for c in cols}
    for i, r in enumerate(rows, start=2):
        try:
            for c in cols:
                out[c].append(float(r[c]))
        except (TypeError, ValueError):
            die("%s:%d: not a number" % (path, i))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--csv", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--title", default="Bandwidth monitor on a rate trace")
    a = ap.parse_args()
    d = read(a.csv)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t, true, est = d["time_s"], d["true_mbitps"], d["estimate_mbitps"]
    fig, ax = plt.subplots(figsize=(9, 4))
    ax.fill_between(t, [0.8 * v for v in true], [1.2 * v for v in true], step="post",
                    color="0.85", label="true rate +-20 %")
    ax.step(t, true, where="post", color="black", lw=1.2, label="true rate")
    ax.plot(t, est, color="tab:blue", lw=1.5, label="monitor estimate")
    top = max(max(true), max(est)) * 1.1 or 1.0
    ax.fill_between(t, 0, top, where=[v == 0 for v in true], step="post", color="tab:red",
                    alpha=0.12, label="true outage")
    det = [x for x, o in zip(t, d["outage"]) if o > 0]
    if det:
        ax.plot(det, [0.02 * top] * len(det), "|", color="tab:red", ms=6, label="outage detected")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("rate [Mbit/s]")
    ax.set_ylim(0, top)
    ax.set_title(a.title)
    ax.legend(loc="upper right", fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    try:
        fig.savefig(a.out, dpi=110)
    except OSError as e:
        die("cannot write %s: %s" % (a.out, e.strerror))


if __name__ == "__main__":
    main()
