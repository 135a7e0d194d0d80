#!/usr/bin/env bash
# ./hermes demo: the whole system on one machine, no downloads but Debian packages.
# Installs what is missing (the ROS-free core packages), builds the ROS-free tools,
# renders three robots in one synthetic hall (EuRoC MH_01..03 ground-truth
# trajectories from 20 s, where they fly: 2, 7.5 and 39 m in 30 s; realistic
# look: motion blur, photon noise, dark regions, aliasing copies, moving objects;
# cached in data_cache/demo after the first run), runs the three agents and the edge
# server in one process over ONE emulated 10 Mbit/s link they all share, and
# prints the report: first what merging gave (robots placed in one map, the map,
# loops between robots, bytes sent, each robot's odometry ATE beside its ATE in
# the merged map) and how to read it, then the details and the paths of the plots.
# Results go to ./results/demo of the working directory (--out), the renders to
# the checkout's data_cache/demo (shared by every run).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
HERMES="$ROOT/hermes"
OUT="results/demo"   # of the working directory, as ./hermes run --out
CACHE="$ROOT/data_cache/demo"
START=20
DURATION=30
RATE=20
BANDWIDTH=10

usage() {
  cat <<'H'
usage: ./hermes demo [--out DIR] [--start S] [--duration S] [--rate HZ] [--bandwidth MBITPS]
                   [--fault jump|drift|none] [--set KEY=VALUE ...] [--plain] [--fresh] [--json]
  Installs what is missing (apt, ROS-free core only), builds, renders three robots
  (EuRoC MH_01..03 trajectories from --start 20 s for --duration 30 s at --rate 20 Hz;
  realistic renders (hermes_sim's default), cached in
  data_cache/demo/s<start>_d<duration>_r<rate>_realistic after the first run), runs
  3 agents + the server over one shared emulated link (default 10 Mbit/s) on a
  simulated clock, prints the report and writes metrics, trajectories and plots under OUT
  (default results/demo in the working directory).
  --fault: what goes wrong with robot MH_03_medium's odometry, for the merge to repair:
  jump (default: a wrong relocalisation, 0.5 m / 10 deg at 15 s), drift (3 % of its path
  for 20 s from 5 s) or none. Its observations stay right, so loops to the others still
  place it; the report names the fault.
  --set KEY=VALUE: any configuration key for the run (docs/configuration.md), repeatable.
  --plain: the plain look instead (every realism effect off; cached in .../s<start>_d<duration>_r<rate>).
  --fresh: render again.  --json: print the metrics JSON instead of the report.
H
}
FRESH=0
JSON=0
FAULT=jump
SETS=()
LOOK=realistic
while [[ $# -gt 0 ]]; do
  case "$1" in
    --help|-h) usage; exit 0 ;;
    --out) OUT="$2"; shift 2 ;;
    --start) START="$2"; shift 2 ;;
    --duration) DURATION="$2"; shift 2 ;;
    --rate) RATE="$2"; shift 2 ;;
    --bandwidth) BANDWIDTH="$2"; shift 2 ;;
    --fault) FAULT="$2"; shift 2 ;;
    --set) SETS+=(--set "$2"); shift 2 ;;
    --fresh) FRESH=1; shift ;;
    --plain) LOOK=plain; shift ;;
    --json) JSON=1; shift ;;
    *) echo "hermes demo: unknown option '$1' (see --help)" >&2; exit 2 ;;
  esac
done

case "$FAULT" in
  jump) SETS=(--set corrupt.agent=MH_03_medium --set corrupt.kind=jump --set corrupt.at_s=15 "${SETS[@]}") ;;
  drift) SETS=(--set corrupt.agent=MH_03_medium --set corrupt.kind=drift --set corrupt.at_s=5
               --set corrupt.drift_duration_s=20 "${SETS[@]}") ;;
  none) ;;
  *) echo "hermes demo: --fault '$FAULT': expected jump, drift or none (see --help)" >&2; exit 2 ;;
esac

GT_DIR="$ROOT/config/trajectories"   # shipped EuRoC ground truth (see its README)
[[ -f "$GT_DIR/MH_01_easy.txt" ]] || { echo "hermes demo: no EuRoC ground-truth trajectories in $GT_DIR" >&2; exit 2; }

for v in "$START" "$DURATION" "$RATE" "$BANDWIDTH"; do
  [[ "$v" =~ ^[0-9]+([.][0-9]+)?$ ]] || { echo "hermes demo: '$v' is not a number (see --help)" >&2; exit 2; }
done

T0=$SECONDS
BIN="${HERMES_BUILD_NOROS_DIR:-$ROOT/build-noros}/bin"   # the tree ./hermes build --no-ros builds
mkdir -p "$OUT" "$CACHE"
BUILD_LOG="$CACHE/build.log"

# Progress of the background jobs every 10 s, when it moved: the build's newest
# percentage (make's "[ NN%]") and the renderer's newest frame counts.
SHOWN=""
SHOWN_AT=$SECONDS
show_progress() {  # show_progress <build pid or ""> <render pid or "">
  local line="" pct frames
  if [[ -n "$1" ]] && kill -0 "$1" 2>/dev/null; then
    pct="$(grep -oE '^\[ *[0-9]+%\]' "$BUILD_LOG" 2>/dev/null | tail -n 1 | tr -d '[] ' || true)"
    line="build ${pct:-starting}"
  fi
  if [[ -n "$2" ]] && kill -0 "$2" 2>/dev/null; then
    frames="$(tr '\r' '\n' <"$LOG" 2>/dev/null | grep -E 'frames' | tail -n 2 | tr '\n' ' ' || true)"
    line+="${line:+  |  }render ${frames:-starting}"
  fi
  (( SECONDS - SHOWN_AT >= 10 )) || return 0
  if [[ -n "$line" && "$line" != "$SHOWN" ]]; then
    echo "[demo]   $((SECONDS - T0)) s: $line" >&2
    SHOWN="$line"; SHOWN_AT=$SECONDS
  fi
}
build_target() {  # build_target <target>: in the background, into $BUILD_LOG
  "$HERMES" build --no-ros --target "$1" >>"$BUILD_LOG" 2>&1 &
  BUILD_PID=$!
}
wait_build() {  # a failed build stops the rendering beside it too
  wait "$BUILD_PID" && return 0
  [[ -n "${SIM:-}" ]] && kill "$SIM" 2>/dev/null
  tail -n 30 "$BUILD_LOG" >&2
  echo "hermes demo: the build failed (log: $BUILD_LOG)" >&2
  exit 1
}

: >"$BUILD_LOG"
echo "[demo] set-up: the Debian packages of the ROS-free core" >&2
"$HERMES" setup --core >&2 || exit 1
echo "[demo] build of the renderer (first time: a few minutes; log $BUILD_LOG)" >&2
build_target hermes_sim
while kill -0 "$BUILD_PID" 2>/dev/null; do sleep 1; show_progress "$BUILD_PID" ""; done
wait_build

KEY="s${START}_d${DURATION}_r${RATE}"
[[ $LOOK == realistic ]] && KEY+="_realistic"
JOBS=$(nproc 2>/dev/null || echo 1); (( JOBS > 3 )) && JOBS=3
LOG="$CACHE/$KEY.log"
SIM=""
if [[ $FRESH -eq 1 || ! -f "$CACHE/$KEY.done" ]]; then
  echo "[demo] rendering 3 robots x ${DURATION} s from ${START} s at ${RATE} Hz, ${LOOK} look, ${JOBS} at once (cached afterwards)" >&2
  rm -rf "${CACHE:?}/$KEY"
  "$BIN/hermes_sim" --trajectory "$GT_DIR/MH_01_easy.txt" --trajectory "$GT_DIR/MH_02_easy.txt" \
    --trajectory "$GT_DIR/MH_03_medium.txt" --out "$CACHE/$KEY" --format euroc \
    --start "$START" --duration "$DURATION" --rate "$RATE" --seed 1 --jobs "$JOBS" --"$LOOK" >"$LOG" 2>&1 &
  SIM=$!
else
  echo "[demo] using cached rendering $CACHE/$KEY" >&2
fi
echo "[demo] build of the runner${SIM:+, beside the rendering}" >&2
build_target hermes_run
while kill -0 "$BUILD_PID" 2>/dev/null || { [[ -n "$SIM" ]] && kill -0 "$SIM" 2>/dev/null; }; do
  sleep 1
  show_progress "$BUILD_PID" "$SIM"
done
wait_build
if [[ -n "$SIM" ]]; then
  wait "$SIM" || { echo "hermes demo: rendering failed (see $LOG)" >&2; exit 1; }
  tr '\r' '\n' <"$LOG" | grep -E 'render [0-9.]+ pairs/s' >&2 || true
  touch "$CACHE/$KEY.done"
fi

echo "[demo] running 3 agents + server over one shared ${BANDWIDTH} Mbit/s link" >&2
RUN_ARGS=(--out "$OUT" --bandwidth "$BANDWIDTH" "${SETS[@]}")
for seq in MH_01_easy MH_02_easy MH_03_medium; do RUN_ARGS+=(--dataset "$CACHE/$KEY/$seq"); done
if [[ $JSON -eq 1 ]]; then
  "$BIN/hermes_run" "${RUN_ARGS[@]}" --json --quiet
  exit 0
fi
REPORT="$("$BIN/hermes_run" "${RUN_ARGS[@]}")"

cat <<REPORT

================ Hermes demo report ================
$REPORT

How to read it: "odometry" is each robot's own tracking against the ground truth, aligned
on its own, in its own frame; it says nothing about where the robot is relative to the
others. "merged" is the robot's place in the one map the server built of all of them
(which no robot has alone), under one alignment for all robots: it counts the robot's own
error and how well it sits relative to the others, so it can lie above its odometry (the
others' error spread over it) or below (loops that fixed its drift). "injected" names the
fault the demo gave one robot's odometry (--fault none: without): its odometry error is
the fault's, its merged error what the loops to the other robots left of it. "sent" is
everything the robots put on the one shared link, against raw streaming of the same maps
and against streaming their cameras.

rendered data : $CACHE/$KEY  (3 robots, EuRoC layout, one shared hall, ${LOOK} look)
metrics       : $OUT/metrics.json
trajectories  : $OUT/trajectories/<robot>_{raw,merged,global,gt}.tum  (odometry, merged map, own world pose, ground truth)
plots         : $OUT/plots/trajectories_top.png
                $OUT/plots/bandwidth.png
                $OUT/plots/ate_over_time.png
total time    : $((SECONDS - T0)) s
====================================================
REPORT
