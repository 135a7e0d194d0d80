#!/usr/bin/python3
"""Plot per-agent uplink bandwidth against the link capacity.

Usage:
  plot_bandwidth.py --csv bandwidth.csv --out bandwidth.png [--title TEXT] [--no-total]

Bandwidth CSV format (written by the offline runner; one header line, comma separated):

  time_s,agent,kBps,link_capacity_kBps
  0.0,agent_0,12.5,125.0
  0.0,agent_1,8.0,125.0
  0.5,agent_0,40.1,125.0
  ...

  time_s              [s] start of the sample interval (simulated clock), non-decreasing
                      per agent;
  agent               agent name (any string without commas);
  kBps                [kB/s, 1 kB = 1000 bytes] bytes the agent actually put on the link
                      during the interval that starts at time_s, divided by its length;
  link_capacity_kBps  [kB/s] link rate available to that agent at time_s (the shared
                      bottleneck rate when several agents share one link; 0 = outage;
                      empty = unknown, not drawn).

Each agent is drawn as a step line; its capacity as a dashed step line in the same
colour, or one black dashed line when every agent reports the same capacity (shared
bottleneck), with the sum over agents ("total") unless --no-total. Outages (capacity 0)
are shaded. Exit code 2 with a one-line reason on bad input.
"""
import argparse
import csv
import sys
from collections import OrderedDict


def die(msg):
    print("plot_bandwidth: " + msg, file=sys.stderr)
    sys.exit(2)


COLUMNS = ("time_s", "agent", "kBps", "link_capacity_kBps")


def read_csv(path):
    """Returns OrderedDict agent -> list of (t, kBps, capacity or None)."""
    try:
        f = open(path, newline="")
    except OSError as e:
        die("cannot open '%s': %s" % (path, e.strerror))
    data = OrderedDict()
    with f:
        reader = csv.reader(f)
        header = next(reader, None)
        if header is None:
            die("'%s' is empty" % path)
        header = [h.strip() for h in header]
        missing = [c for c in COLUMNS if c not in header]
        if missing:
            die("%s:1: missing column(s) %s (header must hold %s)"
                % (path, ", ".join(missing), ",".join(COLUMNS)))
        col = {c: header.index(c) for c in COLUMNS}
        for lineno, row in enumerate(reader, 2):
            if not row or all(not v.strip() for v in row):
                continue
            if len(row) < len(header):
                die("%s:%d: expected %d fields, got %d" % (path, lineno, len(header), len(row)))
            try:
                t = float(row[col["time_s"]])
                rate = float(row[col["kBps"]])
                cap_text = row[col["link_capacity_kBps"]].strip()
                cap = float(cap_text) if cap_text else None
            except ValueError:
                die("%s:%d: time_s, kBps and link_capacity_kBps must be numbers" % (path, lineno))
            agent = row[col["agent"]].strip()
            samples = data.setdefault(agent, [])
            if samples and t < samples[-1][0]:
                die("%s:%d: time_s goes backwards for agent '%s'" % (path, lineno, agent))
            samples.append((t, rate, cap))
    if not data:
        die("'%s' holds no samples" % path)
    return data


def extend(t, y):
    """Step series that also show the last interval (as long as the one before)."""
    t, y = list(t), list(y)
    if len(t) >= 2:
        t.append(t[-1] + (t[-1] - t[-2]))
        y.append(y[-1])
    return t, y


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--csv", required=True, help="bandwidth CSV (format above)")
    ap.add_argument("--out", required=True, help="output PNG")
    ap.add_argument("--title", default="Uplink bandwidth per agent")
    ap.add_argument("--no-total", action="store_true", help="do not draw the sum over agents")
    args = ap.parse_args()
    data = read_csv(args.csv)

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(10, 5))
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    caps = {a: [(t, c) for t, _, c in s if c is not None] for a, s in data.items()}
    shared = len({tuple(v) for v in caps.values()}) == 1
    for k, (agent, samples) in enumerate(data.items()):
        c = colors[k % len(colors)]
        t = [s[0] for s in samples]
        r = [s[1] for s in samples]
        mean = sum(r) / len(r)
        ax.step(*extend(t, r), where="post", color=c, lw=1.5,
                label="%s (mean %.1f, peak %.1f kB/s)" % (agent, mean, max(r)))
        if not shared and caps[agent]:
            ax.step(*extend([x for x, _ in caps[agent]], [y for _, y in caps[agent]]), where="post",
                    color=c, ls="--", lw=1, label="%s link capacity" % agent)
    if shared and caps and next(iter(caps.values())):
        cap = next(iter(caps.values()))
        ax.step(*extend([x for x, _ in cap], [y for _, y in cap]), where="post", color="k", ls="--",
                lw=1.2, label="link capacity (shared)")
        # Shade outages.
        cap_t = extend([x for x, _ in cap], [0] * len(cap))[0]
        for i, (t0, y) in enumerate(cap):
            if y == 0:
                t1 = cap_t[i + 1] if i + 1 < len(cap_t) else t0
                ax.axvspan(t0, t1, color="red", alpha=0.1, lw=0)
        if len(data) > 1 and not args.no_total:
            totals = OrderedDict()
            for samples in data.values():
                for t, r, _ in samples:
                    totals[t] = totals.get(t, 0.0) + r
            ts = sorted(totals)
            ax.step(*extend(ts, [totals[t] for t in ts]), where="post", color="gray", lw=1,
                    alpha=0.8, label="total")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("kB/s")
    ax.set_ylim(bottom=0)
    ax.grid(True, alpha=0.3)
    ax.set_title(args.title)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    try:
        fig.savefig(args.out, dpi=120)
    except OSError as e:
        print("plot_bandwidth: cannot write '%s': %s" % (args.out, e), file=sys.stderr)
        sys.exit(1)
    print("wrote " + args.out, file=sys.stderr)


if __name__ == "__main__":
    main()
