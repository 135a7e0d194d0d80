#!/usr/bin/python3
"""Plot a soak run (hermes bench soak): memory, latency and ATE over the mission.

Usage:
  plot_soak.py --run DIR --out PLOTDIR

Reads DIR/health.csv (the server's health samples: time_s, state_bytes,
rss_bytes, keyframes, pending, submap_ms_median / p95, flying, server_up, ...)
and DIR/ate_over_time.csv (kind `merged`: each merged keyframe's error under the
run's one common alignment; `global`: each robot's own idea of its place at
each frame). Writes PLOTDIR/soak.png: four panels over simulated time - memory
(checkpoint state and resident memory, MB, with the map's keyframes), server time
per submap (median, p95), robots flying and submaps queued, and the merged error
(every keyframe, and its 60-s median). The server crash (metrics.json) is a red line. Exit
code 2 with a one-line reason on bad input.
"""
import argparse
import csv
import json
import os
import sys


def read_csv(path, need):
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if rows and not need.issubset(rows[0].keys()):
        raise ValueError(f"{path}: needs columns {sorted(need)}, has {sorted(rows[0].keys())}")
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--run", required=True, help="the soak's output folder")
    ap.add_argument("--out", required=True, help="folder for soak.png")
    a = ap.parse_args()
    try:
        health = read_csv(os.path.join(a.run, "health.csv"),
                          {"time_s", "state_bytes", "rss_bytes", "keyframes", "pending", "submaps",
                           "submap_ms_median", "submap_ms_p95", "flying", "server_up"})
        ate_path = os.path.join(a.run, "ate_over_time.csv")
        ate = read_csv(ate_path, {"time_s", "agent", "kind", "error_m"}) if os.path.exists(ate_path) else []
    except (OSError, ValueError, KeyError) as e:
        print(f"plot_soak.py: {e}", file=sys.stderr)
        return 2
    if not health:
        print(f"plot_soak.py: {a.run}/health.csv holds no sample", file=sys.stderr)
        return 2
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = [float(r["time_s"]) for r in health]
    up = [r["server_up"] == "1" for r in health]
    fig, ax = plt.subplots(4, 1, figsize=(10, 11), sharex=True)

    # Server crashes (down until re-created from its checkpoint) and robot crashes, from metrics.json.
    downs, crashes = [], []
    try:
        with open(os.path.join(a.run, "metrics.json")) as f:
            m = json.load(f)
        downs = [(r["down_at_s"], r["up_at_s"]) for r in m.get("server_restarts", {}).get("restarts", [])]
    except (OSError, ValueError, KeyError):
        pass

    def shade(axis):
        for d, u in downs:
            axis.axvline(d, color="red", lw=1, alpha=0.7)
            axis.axvspan(d, u, color="red", alpha=0.3, lw=0)

    on = [i for i in range(len(t)) if up[i]]
    ax[0].plot([t[i] for i in on], [float(health[i]["state_bytes"]) / 1e6 for i in on], label="server state (checkpoint) MB")
    ax[0].plot(t, [float(r["rss_bytes"]) / 1e6 for r in health], label="process resident MB (server + agents)")
    ax2 = ax[0].twinx()
    ax2.plot([t[i] for i in on], [int(health[i]["keyframes"]) for i in on], color="grey", ls=":", label="map keyframes")
    ax2.set_ylabel("keyframes")
    ax[0].set_ylabel("MB")
    ax[0].legend(loc="upper left", fontsize=8)
    ax2.legend(loc="lower right", fontsize=8)
    ax[0].set_title("Memory")
    busy = [i for i in range(len(t)) if int(health[i]["submaps"]) > 0]
    ax[1].plot([t[i] for i in busy], [float(health[i]["submap_ms_median"]) for i in busy], ".-", label="median")
    ax[1].plot([t[i] for i in busy], [float(health[i]["submap_ms_p95"]) for i in busy], ".-", label="p95")
    ax[1].set_ylabel("ms")
    ax[1].set_title("Server time per submap (submaps merged in each sample period)")
    ax[1].legend(fontsize=8)
    ax[2].step(t, [int(r["flying"]) for r in health], where="post", label="robots flying")
    ax[2].step(t, [int(r["pending"]) for r in health], where="post", label="submaps queued at the server")
    ax[2].legend(fontsize=8)
    ax[2].set_title("Load")
    merged = sorted((float(r["time_s"]), float(r["error_m"]) * 100) for r in ate if r["kind"] == "merged")
    if merged:
        ax[3].plot([m[0] for m in merged], [m[1] for m in merged], ".", ms=1.5, alpha=0.4, label="merged keyframes")
        bins = {}
        for tm, e in merged:
            bins.setdefault(int(tm // 60), []).append(e)
        keys = sorted(bins)
        med = [sorted(bins[k])[len(bins[k]) // 2] for k in keys]
        ax[3].plot([k * 60 + 30 for k in keys], med, "k-", label="60-s median")
        ax[3].legend(fontsize=8)
    ax[3].set_ylabel("cm")
    ax[3].set_title("Merged map error (one common alignment) by the keyframe's time")
    ax[3].set_xlabel("mission time [s]")
    for axis in ax:
        shade(axis)
        axis.grid(alpha=0.3)
    fig.tight_layout()
    os.makedirs(a.out, exist_ok=True)
    path = os.path.join(a.out, "soak.png")
    fig.savefig(path, dpi=110)
    print(f"plot_soak.py: wrote {path}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
