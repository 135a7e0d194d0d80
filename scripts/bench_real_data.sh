#!/usr/bin/env bash
# Real and published data, one robot each (./hermes run --no-server, default config):
# per clip the frames, lost %, frames skipped, new maps, odometry ATE against the
# published ground truth, and the track stage median / p95. Clips: the ones shipped in
# data/ (data/README.md), the same names under $HERMES_DATA_DIR when set, and any
# dataset folder given with --dataset (any layout ./hermes run reads).
#   ./hermes bench realdata [--dataset DIR ...] [--out DIR] [--json FILE]
# --out: where the runs go (default results/bench_realdata); prints a table.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
OUT="results/bench_realdata"
JSON=""
EXTRA=()
while [[ $# -gt 0 ]]; do
  case "$1" in
    --help|-h) sed -n '2,8p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    --dataset) EXTRA+=("${2:?--dataset needs a folder}"); shift 2 ;;
    --out) OUT="${2:?--out needs a folder}"; shift 2 ;;
    --json) JSON="${2:?--json needs a file}"; shift 2 ;;
    *) echo "bench realdata: unknown option '$1' (see --help)" >&2; exit 2 ;;
  esac
done
CLIPS=(data/euroc_V1_01_micro data/kitti_odometry_06/sequences/06 data/iclnuim_office_kt0/traj0_frei_png)
CLIPS=("${CLIPS[@]/#/$ROOT/}")
if [[ -n "${HERMES_DATA_DIR:-}" ]]; then
  for d in "$HERMES_DATA_DIR"/*/ "$HERMES_DATA_DIR"/*/sequences/*/ "$HERMES_DATA_DIR"/*/*_png/; do
    [[ -d "$d" ]] && CLIPS+=("${d%/}")
  done
fi
CLIPS+=("${EXTRA[@]}")
mkdir -p "$OUT"
rows=()
for d in "${CLIPS[@]}"; do
  [[ -d "$d" ]] || { echo "bench realdata: dataset folder $d does not exist" >&2; exit 2; }
  name="$(echo "${d#$ROOT/}" | tr '/' '_')"
  echo "[realdata] $d" >&2
  if ! "$ROOT/hermes" run --dataset "$d" --out "$OUT/$name" --no-server --quiet >/dev/null 2>"$OUT/$name.log"; then
    echo "bench realdata: the run on $d failed (log: $OUT/$name.log)" >&2
  fi
  rows+=("$d|$OUT/$name/metrics.json")
done
/usr/bin/python3 - "$JSON" "${rows[@]}" <<'PY'
import json, sys
out, rows = sys.argv[1], sys.argv[2:]
table = []
for row in rows:
    clip, path = row.split("|", 1)
    try:
        m = json.load(open(path))
    except (OSError, ValueError):
        table.append({"clip": clip, "error": "no metrics.json"}); continue
    a = m["per_agent"][0]
    t = m.get("timings_ms", {}).get("track", {})
    table.append({"clip": clip, "frames": t.get("count"), "lost_pct": 100 * (a.get("lost_rate") or 0),
                  "frames_skipped": a.get("frames_skipped", 0), "new_maps": a.get("new_maps", 0),
                  "ate_m": a.get("ate_rmse_m"), "track_median_ms": t.get("median"), "track_p95_ms": t.get("p95")})
print("%-62s %6s %7s %7s %5s %9s %10s" % ("clip", "frames", "lost %", "skipped", "maps", "ATE [cm]", "track ms"))
for r in table:
    if "error" in r:
        print("%-62s %s" % (r["clip"][-62:], r["error"])); continue
    ate = "%9.2f" % (100 * r["ate_m"]) if r["ate_m"] is not None else "%9s" % "-"
    print("%-62s %6s %7.1f %7d %5d %s %5.0f/%4.0f" % (r["clip"][-62:], r["frames"], r["lost_pct"], r["frames_skipped"],
          r["new_maps"] + 1, ate, r["track_median_ms"] or 0, r["track_p95_ms"] or 0))
if out:
    json.dump({"clips": table}, open(out, "w"), indent=2)
PY
