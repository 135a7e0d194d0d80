#!/usr/bin/env bash
# Issue #5 acceptance: over a real `tc tbf` link between two network namespaces,
# the bandwidth monitor (hermes_link_probe send) must agree with iperf3's measured
# goodput within 15 %. Prints one JSON line: iperf3_mbps, monitor_mbps (median of
# the monitor's estimates), probe_goodput_mbps, rel_diff, pass.
#   scripts/tbf_monitor_check.sh [--rate-mbit 10] [--seconds 20] [--message-bytes B]
#                                [--probe BIN] [--json FILE] [--keep-logs]
# Needs root, ip netns, tc and iperf3; otherwise prints "SKIP: <reason>" and exits 77.
# Exit status: 0 pass, 1 measured but outside 15 %, 2 usage, 3 setup/run failure.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
RATE=10
SECONDS_RUN=20
MESSAGE_BYTES=262144
PROBE="$ROOT/build-noros/bin/hermes_link_probe"
JSON=""
KEEP_LOGS=0
while [[ $# -gt 0 ]]; do
  case "$1" in
    --help|-h) sed -n '2,9p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    --rate-mbit) RATE="$2"; shift 2 ;;
    --seconds) SECONDS_RUN="$2"; shift 2 ;;
    --message-bytes) MESSAGE_BYTES="$2"; shift 2 ;;
    --probe) PROBE="$2"; shift 2 ;;
    --json) JSON="$2"; shift 2 ;;
    --keep-logs) KEEP_LOGS=1; shift ;;
    *) echo "tbf_monitor_check: unknown option '$1' (see --help)" >&2; exit 2 ;;
  esac
done

skip() { echo "SKIP: $*"; exit 77; }
fail() { echo "tbf_monitor_check: $*" >&2; exit 3; }

[[ "$(id -u)" == 0 ]] || skip "needs root (network namespaces and tc)"
command -v ip >/dev/null || skip "ip (iproute2) is not installed"
command -v tc >/dev/null || skip "tc (iproute2) is not installed"
command -v iperf3 >/dev/null || skip "iperf3 is not installed (apt-get install iperf3)"
[[ -x "$PROBE" ]] || fail "probe binary $PROBE not found (build target hermes_link_probe)"

NS_A="hermes_tbf_a_$$"
NS_B="hermes_tbf_b_$$"
VETH_A="htbfa$$"
VETH_B="htbfb$$"
VETH_A="${VETH_A:0:15}"
VETH_B="${VETH_B:0:15}"
ADDR_A=10.77.0.1
ADDR_B=10.77.0.2
LOGS="$(mktemp -d /tmp/hermes_tbf.XXXXXX)"
PIDS=()

cleanup() {
  for pid in "${PIDS[@]}"; do kill "$pid" 2>/dev/null || true; done
  ip netns del "$NS_A" 2>/dev/null || true
  ip netns del "$NS_B" 2>/dev/null || true
  if [[ "$KEEP_LOGS" == 1 ]]; then echo "tbf_monitor_check: logs in $LOGS" >&2; else rm -rf "$LOGS"; fi
}
trap cleanup EXIT

ip netns add "$NS_A" 2>"$LOGS/netns.err" || skip "ip netns add failed: $(cat "$LOGS/netns.err")"
ip netns add "$NS_B" 2>"$LOGS/netns.err" || skip "ip netns add failed: $(cat "$LOGS/netns.err")"
ip link add "$VETH_A" netns "$NS_A" type veth peer name "$VETH_B" netns "$NS_B" ||
  fail "creating the veth pair $VETH_A/$VETH_B failed"
ip -n "$NS_A" addr add "$ADDR_A/24" dev "$VETH_A"
ip -n "$NS_B" addr add "$ADDR_B/24" dev "$VETH_B"
for ns in "$NS_A" "$NS_B"; do ip -n "$ns" link set lo up; done
ip -n "$NS_A" link set "$VETH_A" up
ip -n "$NS_B" link set "$VETH_B" up
# veth offloads would hand tbf 64 kB super-packets; real links carry MTU frames.
ip netns exec "$NS_A" ethtool -K "$VETH_A" tso off gso off >/dev/null 2>&1 || true
ip netns exec "$NS_A" tc qdisc add dev "$VETH_A" root tbf rate "${RATE}mbit" burst 32kbit latency 50ms ||
  fail "tc qdisc add tbf on $VETH_A failed"

wait_for() {  # wait_for <file> <text>: up to 5 s
  for _ in $(seq 50); do grep -q "$2" "$1" 2>/dev/null && return 0; sleep 0.1; done
  return 1
}

# 1) iperf3: the independent goodput measurement (receiver side).
ip netns exec "$NS_B" iperf3 -s -1 --forceflush -B "$ADDR_B" -p 5201 >"$LOGS/iperf3_server.log" 2>&1 &
PIDS+=($!)
wait_for "$LOGS/iperf3_server.log" "listening" || fail "iperf3 server did not start: $(cat "$LOGS/iperf3_server.log")"
ip netns exec "$NS_A" iperf3 -c "$ADDR_B" -p 5201 -t "$SECONDS_RUN" -J >"$LOGS/iperf3.json" 2>"$LOGS/iperf3.err" ||
  fail "iperf3 client failed: $(cat "$LOGS/iperf3.err") $(head -c 400 "$LOGS/iperf3.json")"

# 2) The probe: the monitor fed by real send/ack times over the same link.
ip netns exec "$NS_B" "$PROBE" serve --bind "$ADDR_B" --port 5301 >"$LOGS/probe_server.log" 2>&1 &
PIDS+=($!)
wait_for "$LOGS/probe_server.log" "listening" || fail "probe server did not start: $(cat "$LOGS/probe_server.log")"
ip netns exec "$NS_A" "$PROBE" send --host "$ADDR_B" --port 5301 --seconds "$SECONDS_RUN" \
  --message-bytes "$MESSAGE_BYTES" --json "$LOGS/probe.json" --trace "$LOGS/probe_trace.csv" \
  >/dev/null 2>"$LOGS/probe.err" || fail "probe send failed: $(cat "$LOGS/probe.err")"

RESULT="$(/usr/bin/python3 - "$LOGS/iperf3.json" "$LOGS/probe.json" "$RATE" <<'PY'
import json, sys
ip = json.load(open(sys.argv[1]))
if "error" in ip:
    sys.exit("iperf3 reported: " + ip["error"])
iperf = ip["end"]["sum_received"]["bits_per_second"] / 1e6
probe = json.load(open(sys.argv[2]))
mon = probe["monitor_median_mbps"]
rel = abs(mon - iperf) / iperf
print(json.dumps({"rate_mbit": float(sys.argv[3]), "iperf3_mbps": round(iperf, 3),
                  "monitor_mbps": round(mon, 3),
                  "monitor_final_mbps": round(probe["monitor_estimate_mbps"], 3),
                  "probe_goodput_mbps": round(probe["goodput_mbps"], 3),
                  "rel_diff": round(rel, 4), "pass": rel <= 0.15,
                  "message_bytes": probe["message_bytes"], "samples": probe["samples"]}))
PY
)" || fail "could not read the measurements"
echo "$RESULT"
[[ -z "$JSON" ]] || echo "$RESULT" >"$JSON"
[[ "$RESULT" == *'"pass": true'* ]]
