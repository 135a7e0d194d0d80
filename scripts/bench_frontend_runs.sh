#!/usr/bin/env bash
# Front-end acceptance runs (issue: agent front end): renders the first S seconds
# (default 60) of MH_01 and V1_01 as stereo and of MH_02 as RGB-D (cached in
# data_cache/frontend), tracks each with one agent (hermes_run --no-server) and
# prints a JSON table: ATE, lost rate, keyframes, frames/s.
#   scripts/bench_frontend_runs.sh [--duration S] [--out DIR]
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
DURATION=60
OUT="$ROOT/results/frontend_runs"
while [[ $# -gt 0 ]]; do
  case "$1" in
    --help|-h) sed -n '2,7p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    --duration) DURATION="$2"; shift 2 ;;
    --out) OUT="$2"; shift 2 ;;
    *) echo "bench_frontend_runs: unknown option '$1'" >&2; exit 2 ;;
  esac
done
BIN="$ROOT/build-noros/bin"
[[ -x "$BIN/hermes_run" ]] || "$ROOT/hermes" build --no-ros >/dev/null
CACHE="$ROOT/data_cache/frontend/d$DURATION"
GT="$ROOT/config/trajectories"
mkdir -p "$CACHE" "$OUT"
render() {  # render <name> <trajectory> <format>
  local dir="$CACHE/$1"
  if [[ ! -f "$dir/done" ]]; then
    echo "[frontend] rendering $1 ($3, ${DURATION} s)" >&2
    rm -rf "$dir"
    "$BIN/hermes_sim" --trajectory "$GT/$2.txt" --out "$dir" --format "$3" --duration "$DURATION" \
      --seed 1 --plain >/dev/null 2>&1   # the look of its published figures
    touch "$dir/done"
  fi
  echo "$dir/$2"
}
ROWS=()
for spec in "mh01_stereo MH_01_easy euroc 0.05" "v101_stereo V1_01_easy euroc 0.05" "mh02_rgbd MH_02_easy tum 0.03"; do
  read -r name traj fmt bound <<<"$spec"
  data="$(render "$name" "$traj" "$fmt")"
  echo "[frontend] tracking $name" >&2
  "$BIN/hermes_run" --dataset "$data" --no-server --out "$OUT/$name" --quiet --json >"$OUT/$name.json"
  ROWS+=("$(/usr/bin/python3 - "$OUT/$name.json" "$name" "$bound" <<'PY'
import json, sys
m = json.load(open(sys.argv[1])); a = m["per_agent"][0]
t = m["timings_ms"].get("track", {})
ate = a["ate_rmse_m"]
print(json.dumps({"run": sys.argv[2], "ate_rmse_m": ate, "bound_m": float(sys.argv[3]),
                  "pass": ate is not None and ate <= float(sys.argv[3]) and a["lost_rate"] < 0.01,
                  "lost_rate": a["lost_rate"], "keyframes": a["keyframes"],
                  "track_ms_median": t.get("median"), "track_ms_p95": t.get("p95")}))
PY
)")
done
printf '{"duration_s": %s, "runs": [%s]}\n' "$DURATION" "$(IFS=,; echo "${ROWS[*]}")"
