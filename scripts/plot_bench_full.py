#!/usr/bin/python3
"""Plot a whole-sequence table (`./hermes bench system --full`): merged ATE and
bytes against the shared link's bandwidth, one line per variant (paper Fig. 13/16).

Usage:
  plot_bench_full.py --json OUT/bench_system_full.json --out OUT/plots

Writes ate_vs_bandwidth.png and bytes_vs_bandwidth.png. Unlimited (0 Mbit/s) is
drawn at the right end, labelled "unlim.". A run that merged fewer robots than it
had is marked with its count ("3/5"). Exit code 2 with a one-line reason on bad input.
"""
import argparse
import json
import os
import sys


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", required=True, help="bench_system_full.json")
    ap.add_argument("--out", required=True, help="output folder")
    a = ap.parse_args()
    try:
        with open(a.json) as f:
            runs = json.load(f)["runs"]
    except (OSError, ValueError, KeyError) as e:
        print(f"plot_bench_full.py: {a.json}: {e}", file=sys.stderr)
        return 2
    if not runs:
        print(f"plot_bench_full.py: {a.json}: no runs", file=sys.stderr)
        return 2
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    limited = sorted({r["bandwidth_mbitps"] for r in runs if r["bandwidth_mbitps"] > 0})
    unlim_x = (max(limited) * 3) if limited else 1.0
    def x_of(bw):
        return bw if bw > 0 else unlim_x

    variants = []
    for r in runs:
        if r["variant"] not in variants:
            variants.append(r["variant"])
    os.makedirs(a.out, exist_ok=True)
    for key, scale, ylabel, name in (("ate_rmse_m", 100.0, "merged ATE, all robots [cm]", "ate_vs_bandwidth.png"),
                                     ("bytes_total", 1e-6, "bytes sent [MB]", "bytes_vs_bandwidth.png")):
        fig, ax = plt.subplots(figsize=(6.4, 4.2))
        for v in variants:
            pts = sorted((x_of(r["bandwidth_mbitps"]), r.get(key), r.get("agents_merged", 0), r.get("agents", 0))
                         for r in runs if r["variant"] == v and r.get(key) is not None)
            if not pts:
                continue
            ax.plot([p[0] for p in pts], [p[1] * scale for p in pts], marker="o", label=v)
            for x, y, merged, agents in pts:
                if merged < agents:
                    ax.annotate(f"{merged}/{agents}", (x, y * scale), textcoords="offset points",
                                xytext=(4, 4), fontsize=8)
        ax.set_xscale("log")
        ax.minorticks_off()
        ticks = limited + [unlim_x]
        ax.set_xticks(ticks)
        ax.set_xticklabels([f"{t:g}" for t in limited] + ["unlim."])
        ax.set_xlabel("shared link [Mbit/s]")
        ax.set_ylabel(ylabel)
        ax.grid(True, alpha=0.3)
        ax.legend()
        fig.tight_layout()
        fig.savefig(os.path.join(a.out, name), dpi=120)
        plt.close(fig)
    return 0


if __name__ == "__main__":
    sys.exit(main())
