#!/usr/bin/env bash
# Real time through ROS (issue: real robots): one Agent nodelet fed by `rosbag play`
# at 1.0x, as a robot's camera would feed it: stereo (original EuRoC layout, raw
# distorted, 20 Hz) and RGB-D (original TUM layout, 30 Hz), each a render of S
# seconds (default 30; cached in data_cache/realtime). Default image queues (the
# agent drops what it cannot take in time). Prints per input: frames in the bag,
# received, tracked (fraction), latency stamp -> pose median / p95 / max, the
# agent's track stage median / p95 (and their ratio), its process CPU [cores] and
# odometry ATE; and the machine's load average. Not a test: numbers depend on load.
#   ./hermes bench realtime [--duration S] [--json FILE] [--keep]
# Needs the ROS build (./hermes build).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BUILD="${HERMES_BUILD_DIR:-$ROOT/build}"
DURATION=30
JSON=""
KEEP=0
while [[ $# -gt 0 ]]; do
  case "$1" in
    --help|-h) sed -n '2,10p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    --duration) DURATION="${2:?--duration needs seconds}"; shift 2 ;;
    --json) JSON="${2:?--json needs a file}"; shift 2 ;;
    --keep) KEEP=1; shift ;;
    *) echo "bench realtime: unknown option '$1' (see --help)" >&2; exit 2 ;;
  esac
done
[[ "$DURATION" =~ ^[0-9]+$ && "$DURATION" -ge 5 ]] || { echo "bench realtime: --duration must be an integer >= 5 (got '$DURATION')" >&2; exit 2; }
for f in "$BUILD/devel/setup.bash" "$BUILD/bin/hermes_sim" "$BUILD/bin/hermes_dataset_to_bag" \
         "$BUILD/devel/lib/hermes_tests/test_bag_input"; do
  [[ -e "$f" ]] || { echo "bench realtime: $f is missing: run ./hermes build first" >&2; exit 2; }
done
set +u; source "$BUILD/devel/setup.bash"; set -u

CACHE="$ROOT/data_cache/realtime/d$DURATION"
mkdir -p "$CACHE"
if [[ ! -f "$CACHE/done" ]]; then
  echo "[realtime] rendering ${DURATION} s of stereo (20 Hz) and RGB-D (30 Hz), writing bags ..." >&2
  GT="$ROOT/config/trajectories"
  "$BUILD/bin/hermes_sim" --trajectory "$GT/MH_01_easy.txt" --out "$CACHE/euroc" --duration "$DURATION" --rate 20 --seed 1 --plain >/dev/null 2>&1
  "$BUILD/bin/hermes_sim" --trajectory "$GT/MH_02_easy.txt" --out "$CACHE/tum" --format tum --duration "$DURATION" --rate 30 --seed 2 --plain >/dev/null 2>&1
  "$BUILD/bin/hermes_dataset_to_bag" --dataset "$CACHE/euroc/MH_01_easy" --out "$CACHE/euroc.bag" --layout euroc 2>/dev/null
  "$BUILD/bin/hermes_dataset_to_bag" --dataset "$CACHE/tum/MH_02_easy" --out "$CACHE/tum.bag" --layout tum 2>/dev/null
  touch "$CACHE/done"
fi

WORK="$(mktemp -d /tmp/hermes_bench_realtime.XXXXXX)"
[[ "$KEEP" == 1 ]] || trap 'rm -rf "$WORK"' EXIT
TIMEOUT=$((DURATION * 3 + 60))
"$ROOT/scripts/keys.sh" add R --dir "$WORK/keys" >/dev/null  # a throw-away key: frames tagged as on a robot

# run_one NAME CAMERA MODE BAG DATA IMAGE_TOPIC
run_one() {
  local name="$1" camera="$2" mode="$3" bag="$4" data="$5" topic="$6"
  cat > "$WORK/$name.test" <<EOF
<launch>
  <include file="\$(find hermes_agent)/launch/agent.launch">
    <arg name="robot" value="R"/>
    <arg name="camera" value="$camera"/>
    <arg name="mode" value="$mode"/>
    <arg name="clear_spool" value="true"/>
    <arg name="spool_dir" value="$WORK/spool_$name"/>
    <arg name="key_file" value="$WORK/keys/R.key"/>
  </include>
  <node pkg="rosbag" type="play" name="play" args="--wait-for-subscribers -d 1 $bag" required="false"/>
  <test test-name="$name" pkg="hermes_tests" type="test_bag_input" time-limit="$((TIMEOUT + 30)).0">
    <param name="data" value="$data"/>
    <param name="robot" value="R"/>
    <param name="image_topic" value="$topic"/>
    <param name="max_ate" value="1.0"/>
    <param name="min_tracked" value="0.0"/>
    <param name="timeout_s" value="$TIMEOUT"/>
    <param name="report" value="$WORK/$name.json"/>
  </test>
</launch>
EOF
  echo "[realtime] $name: playing the ${DURATION}-s bag at 1.0x into one Agent nodelet ..." >&2
  if ! rostest --pkgdir="$ROOT/test" --package=hermes_tests --text "$WORK/$name.test" \
       > "$WORK/$name.log" 2>&1; then
    echo "[realtime] $name: rostest reported a failure (see $WORK/$name.log with --keep); its numbers are still reported" >&2
  fi
  [[ -s "$WORK/$name.json" ]] || { echo "bench realtime: $name wrote no report; log tail:" >&2; tail -20 "$WORK/$name.log" >&2; exit 1; }
}

run_one stereo euroc stereo "$CACHE/euroc.bag" "$CACHE/euroc/MH_01_easy" /cam0/image_raw
run_one rgbd "$CACHE/tum/MH_02_easy/camera.yaml" rgbd "$CACHE/tum.bag" "$CACHE/tum/MH_02_easy" /camera/rgb/image_color

/usr/bin/python3 - "$WORK" "$DURATION" "${JSON:-}" <<'PY'
import json, os, sys
work, duration, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
res = {"duration_s": duration, "loadavg_1min": os.getloadavg()[0], "nproc": os.cpu_count(), "inputs": {}}
for name, rate in (("stereo", 20), ("rgbd", 30)):
    r = json.load(open(os.path.join(work, name + ".json")))
    t = r.get("agent_timings_ms", {}).get("track", {})
    received = r["agent_frames"].get("fed", 0)
    res["inputs"][name] = {
        "rate_hz": rate, "frames": r["frames"], "fed": received, "tracked": r["tracked"],
        "tracked_fraction": r["tracked_fraction"], "latency_ms": r["latency_ms"],
        "track_ms": {"median": t.get("median"), "p95": t.get("p95")},
        "track_p95_over_median": (t["p95"] / t["median"]) if t.get("median") else None,
        "cpu_cores": r.get("cpu_cores"), "ate_m": r.get("ate_m")}
text = json.dumps(res, indent=2)
if out:
    open(out, "w").write(text + "\n")
print(text)
PY
