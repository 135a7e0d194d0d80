#!/usr/bin/env bash
# Headless rviz screenshot of a live merge: starts Xvfb, runs demo.launch (server,
# three agents playing rendered sequences, rviz with config/rviz/hermes.rviz),
# waits, and saves the screen as a PNG.
#   scripts/rviz_screenshot.sh [--out results/rviz/merged.png] [--wait S] [--data DIR] [--rate X]
# Needs the ROS build (./hermes build) and rendered data (default: the demo's cache,
# rendered by ./hermes demo; --data DIR: a folder with MH_01_easy, MH_02_easy, MH_03_medium).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
OUT="$ROOT/results/rviz/merged.png"
WAIT=150
DATA="$ROOT/data_cache/demo/s20_d30_r20_realistic"
RATE=0.25
while [[ $# -gt 0 ]]; do
  case "$1" in
    --help|-h) sed -n '2,8p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    --out) OUT="$2"; shift 2 ;;
    --wait) WAIT="$2"; shift 2 ;;
    --data) DATA="$2"; shift 2 ;;
    --rate) RATE="$2"; shift 2 ;;
    *) echo "rviz_screenshot: unknown option '$1'" >&2; exit 2 ;;
  esac
done
[[ -d "$DATA/MH_01_easy" ]] || { echo "rviz_screenshot: no rendered data in $DATA (run ./hermes demo first, or --data DIR)" >&2; exit 2; }
[[ -f "$ROOT/build/devel/setup.bash" ]] || { echo "rviz_screenshot: no ROS build (run ./hermes build)" >&2; exit 2; }
command -v Xvfb >/dev/null && command -v import >/dev/null || { echo "rviz_screenshot: Xvfb/import missing (run ./hermes setup)" >&2; exit 2; }
mkdir -p "$(dirname "$OUT")"
set +u
# shellcheck disable=SC1091
source "$ROOT/build/devel/setup.bash"
set -u
export DISPLAY=:77
Xvfb :77 -screen 0 1280x800x24 -nolisten tcp >/dev/null 2>&1 &
XPID=$!
trap 'kill $LPID 2>/dev/null || true; wait $LPID 2>/dev/null || true; kill $XPID 2>/dev/null || true; rm -rf "${KEYS:-}"' EXIT
sleep 1
KEYS="$(mktemp -d /tmp/hermes_rviz_keys.XXXXXX)"  # authenticated like a deployment, throw-away keys
for robot in agent0 agent1 agent2; do "$ROOT/scripts/keys.sh" add "$robot" --dir "$KEYS" >/dev/null; done
echo "[rviz] running server + 3 agents + rviz for ${WAIT} s"
roslaunch hermes_agent demo.launch data:="$DATA" rviz:=true rate:=$RATE key_dir:="$KEYS" >/tmp/hermes_rviz_launch.log 2>&1 &
LPID=$!
sleep "$WAIT"
import -window root "$OUT"
echo "[rviz] screenshot: $OUT"
