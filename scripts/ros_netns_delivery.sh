#!/usr/bin/env bash
# Issue #5 acceptance: exactly-once submap delivery through real ROS topics between
# two network namespaces, under 20 % packet loss, a 30 s link outage and a SIGKILL +
# restart of the agent's whole roslaunch in the middle of the run.
#   server namespace (10.78.0.2): roscore, hermes_server_node, a monitor (acks, /hermes/status)
#   agent namespace  (10.78.0.1): agent.launch (DatasetPlayer + Agent nodelets, one robot on
#                                 the rendered rostest data), a monitor (<robot>/uplink_status)
# Loss: nftables netdev rules on the agent's veth, BOTH directions (ingress and egress hooks,
# `numgen random mod 100 < N drop`); the outage drops everything on both hooks for --outage-s.
# Timeline from the agent's first submap (so that the nodes are up): the link is cut at the
# first new submap after --outage-at s (so one is in flight), for --outage-s; --kill-after s
# after it is back, as soon as the agent reports an unacknowledged submap (at most 10 s
# later), its roslaunch and all its nodes (each in a process group of its own) get SIGKILL;
# --restart-delay s later it is restarted with the same spool (clear_spool:=false).
# Then waits until the agent's spool is empty and the server applied what was sent.
# Prints one JSON line (sent / applied / duplicates / lost / spool max vs cap / crashes / pass).
#   scripts/ros_netns_delivery.sh [--json FILE] [--loss-pct 20] [--outage-s 30] [--outage-at 10]
#       [--kill-after 3] [--restart-delay 2] [--rate 0.2] [--window-s 1] [--spool-cap-mb MB]
#       [--drain-timeout 60] [--build DIR] [--keep-logs] [--clear-spool-on-restart]
# --clear-spool-on-restart (negative control): the restart drops the spool's backlog; the run
# fails if a dropped submap had not reached the server yet (lost), passes if it had.
# Needs root, ip netns and nft; otherwise prints "SKIP: <reason>" and exits 77.
# Exit status: 0 pass, 1 delivery check failed, 2 usage, 3 setup/run failure.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
PY=/usr/bin/python3
BUILD="${HERMES_BUILD_DIR:-$ROOT/build}"
JSON=""
LOSS=20
OUTAGE_S=30
OUTAGE_AT=3
KILL_AFTER=3
RESTART_DELAY=2
RATE=0.2
WINDOW_S=1
SPOOL_CAP_MB=""   # empty: the project's uplink.buffer.max_mbytes
DRAIN_TIMEOUT=60
KEEP_LOGS=0
ROBOT=agent0
RESTART_CLEAR=false
while [[ $# -gt 0 ]]; do
  case "$1" in
    --help|-h) sed -n '2,23p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    --json) JSON="$2"; shift 2 ;;
    --loss-pct) LOSS="$2"; shift 2 ;;
    --outage-s) OUTAGE_S="$2"; shift 2 ;;
    --outage-at) OUTAGE_AT="$2"; shift 2 ;;
    --kill-after) KILL_AFTER="$2"; shift 2 ;;
    --restart-delay) RESTART_DELAY="$2"; shift 2 ;;
    --rate) RATE="$2"; shift 2 ;;
    --window-s) WINDOW_S="$2"; shift 2 ;;
    --spool-cap-mb) SPOOL_CAP_MB="$2"; shift 2 ;;
    --drain-timeout) DRAIN_TIMEOUT="$2"; shift 2 ;;
    --build) BUILD="$2"; shift 2 ;;
    --keep-logs) KEEP_LOGS=1; shift ;;
    --clear-spool-on-restart) RESTART_CLEAR=true; shift ;;
    *) echo "ros_netns_delivery: unknown option '$1' (see --help)" >&2; exit 2 ;;
  esac
done

skip() { echo "SKIP: $*"; exit 77; }
fail() { echo "ros_netns_delivery: $*" >&2; exit 3; }
log() { printf '[%6.1f s] %s\n' "$(elapsed)" "$*" >&2; }

[[ "$(id -u)" == 0 ]] || skip "needs root (network namespaces and nftables)"
command -v ip >/dev/null || skip "ip (iproute2) is not installed"
command -v nft >/dev/null || skip "nft (nftables) is not installed"
command -v roslaunch >/dev/null || skip "roslaunch is not installed (./hermes setup)"
command -v roscore >/dev/null || skip "roscore is not installed (./hermes setup)"
[[ -d "$BUILD" ]] || fail "--build $BUILD: no such folder"
BUILD="$(cd "$BUILD" && pwd)"  # roslaunch runs its nodes elsewhere: an absolute path
DATA="$BUILD/rostest_data/hall_d10_r10/MH_01_easy"
[[ -f "$BUILD/devel/setup.bash" ]] || fail "$BUILD/devel/setup.bash not found: build the ROS tree first (./hermes build)"
[[ -d "$DATA" ]] || fail "rendered data $DATA not found (build target hermes_tests_multi_agent_data)"
[[ -f "$BUILD/devel/lib/libhermes_agent_nodelets.so" ]] || fail "agent nodelets not built in $BUILD"
[[ -x "$BUILD/devel/lib/hermes_server/hermes_server_node" ]] || fail "hermes_server_node not built in $BUILD"

NS_S="hermes_dlv_s_$$"
NS_A="hermes_dlv_a_$$"
VETH_A="hdlva$$"; VETH_A="${VETH_A:0:15}"
VETH_S="hdlvs$$"; VETH_S="${VETH_S:0:15}"
ADDR_A=10.78.0.1
ADDR_S=10.78.0.2
MASTER="http://$ADDR_S:11311"
LOGS="$(mktemp -d /tmp/hermes_netns_delivery.XXXXXX)"
SPOOL="$LOGS/spool/$ROBOT"
T_START=$(date +%s.%N)
elapsed() { awk -v a="$T_START" -v b="$(date +%s.%N)" 'BEGIN{printf "%.1f", b-a}'; }
PGIDS=()   # process groups we started (each launched through setsid)

stop_group() {  # stop_group <pgid> <signal>
  kill "-$2" -- "-$1" 2>/dev/null || true
}
tree() {  # tree <pid>...: the pids and all their descendants
  ps -e -o pid=,ppid= | awk -v roots="$*" '
    BEGIN { n = split(roots, r, " "); for (i = 1; i <= n; i++) keep[r[i]] = 1 }
    { parent[$1] = $2 }
    END { do { changed = 0
            for (p in parent) if (!(p in keep) && (parent[p] in keep)) { keep[p] = 1; changed = 1 }
          } while (changed)
          for (p in keep) if (p in parent) print p }'
}
alive() {  # alive <pid>...: those still running (zombies do not count)
  local p st
  for p in "$@"; do
    st=$(ps -o stat= -p "$p" 2>/dev/null || true)
    [[ -n "$st" && "$st" != Z* ]] && echo "$p"
  done
  return 0
}
cleanup() {
  local rc=$?
  # roslaunch puts every node in a session of its own: remember the whole trees first.
  local pids; pids=$(tree "${PGIDS[@]}")
  for g in "${PGIDS[@]}"; do stop_group "$g" INT; done
  for _ in $(seq 30); do
    [[ -z "$(alive $pids)" ]] && break
    sleep 0.2
  done
  for p in $pids; do kill -KILL "$p" 2>/dev/null || true; done
  ip netns del "$NS_A" 2>/dev/null || true
  ip netns del "$NS_S" 2>/dev/null || true
  if [[ "$KEEP_LOGS" == 1 || $rc -ne 0 ]]; then echo "ros_netns_delivery: logs in $LOGS" >&2; else rm -rf "$LOGS"; fi
}
trap cleanup EXIT
trap 'exit 130' INT TERM

# ---------------------------------------------------------------- network
ip netns add "$NS_S" 2>"$LOGS/netns.err" || skip "ip netns add failed: $(cat "$LOGS/netns.err")"
ip netns add "$NS_A" 2>"$LOGS/netns.err" || skip "ip netns add failed: $(cat "$LOGS/netns.err")"
ip link add "$VETH_A" netns "$NS_A" type veth peer name "$VETH_S" netns "$NS_S" ||
  fail "creating the veth pair $VETH_A/$VETH_S failed"
ip -n "$NS_A" addr add "$ADDR_A/24" dev "$VETH_A"
ip -n "$NS_S" addr add "$ADDR_S/24" dev "$VETH_S"
for ns in "$NS_A" "$NS_S"; do ip -n "$ns" link set lo up; done
# One MTU frame per packet (no 64 kB GSO super-packets), so that N % loss is per frame.
ip -n "$NS_A" link set "$VETH_A" gso_max_size 1500 gso_max_segs 1 2>/dev/null || true
ip -n "$NS_S" link set "$VETH_S" gso_max_size 1500 gso_max_segs 1 2>/dev/null || true
ip -n "$NS_A" link set "$VETH_A" up
ip -n "$NS_S" link set "$VETH_S" up
# Loss on both directions of the agent's veth; the cut_* chains (empty unless the link is
# cut) come first. The first rule of in/out counts every packet, the second drops N %.
ip netns exec "$NS_A" nft -f - 2>"$LOGS/nft.err" <<EOF || skip "nftables netdev ingress/egress hooks unavailable: $(cat "$LOGS/nft.err")"
table netdev hermes_delivery {
  chain cut_in {
    type filter hook ingress device "$VETH_A" priority -10;
  }
  chain cut_out {
    type filter hook egress device "$VETH_A" priority -10;
  }
  chain in {
    type filter hook ingress device "$VETH_A" priority 0;
    counter
    numgen random mod 100 < $LOSS counter drop
  }
  chain out {
    type filter hook egress device "$VETH_A" priority 0;
    counter
    numgen random mod 100 < $LOSS counter drop
  }
}
EOF
link_cut() {
  ip netns exec "$NS_A" nft add rule netdev hermes_delivery cut_in counter drop
  ip netns exec "$NS_A" nft add rule netdev hermes_delivery cut_out counter drop
}
link_restore() {
  ip netns exec "$NS_A" nft flush chain netdev hermes_delivery cut_in
  ip netns exec "$NS_A" nft flush chain netdev hermes_delivery cut_out
}

# ---------------------------------------------------------------- ROS
set +u; source "$BUILD/devel/setup.bash"; set -u
export ROS_MASTER_URI="$MASTER" ROS_HOME="$LOGS/ros_home" PYTHONUNBUFFERED=1
mkdir -p "$ROS_HOME" "$(dirname "$SPOOL")"
# The project's config with short windows (the rendered sequence is 10 s) and the spool cap.
cp "$ROOT/config/hermes.yaml" "$LOGS/config.yaml"
if [[ -n "$SPOOL_CAP_MB" ]]; then
  sed -i -e "s/^\(    max_mbytes:\) *[0-9.]*/\1 $SPOOL_CAP_MB/" "$LOGS/config.yaml"
  grep -q "^    max_mbytes: $SPOOL_CAP_MB" "$LOGS/config.yaml" || fail "could not set uplink.buffer.max_mbytes in the config copy"
fi
printf 'window:\n  period_s: %s\n' "$WINDOW_S" >>"$LOGS/config.yaml"

start_in() {  # start_in <ns> <ip> <log> cmd...: new process group, echoes its pgid
  local ns="$1" addr="$2" out="$3"; shift 3
  # stdbuf: line-buffered logs from the nodes too (their stdout is a file).
  ip netns exec "$ns" env ROS_IP="$addr" setsid stdbuf -oL -eL "$@" >"$out" 2>&1 </dev/null &
  echo $!
}
wait_master() {
  for _ in $(seq 60); do
    ip netns exec "$1" env ROS_IP="$2" timeout 5 rostopic list >/dev/null 2>&1 && return 0
    sleep 0.5
  done
  return 1
}
wait_file() {  # wait_file <file> <text> <seconds>
  for _ in $(seq $(( $3 * 5 ))); do grep -q "$2" "$1" 2>/dev/null && return 0; sleep 0.2; done
  return 1
}

# Authentication on, as the launch files default to: this run's own keys.
"$ROOT/scripts/keys.sh" add "$ROBOT" --dir "$LOGS/keys" >/dev/null || fail "cannot create the robot's key"
G=$(start_in "$NS_S" "$ADDR_S" "$LOGS/roscore.log" roscore -p 11311); PGIDS+=("$G"); G_CORE=$G
wait_master "$NS_S" "$ADDR_S" || fail "roscore did not come up: $(tail -5 "$LOGS/roscore.log")"
wait_master "$NS_A" "$ADDR_A" || fail "the master is not reachable from the agent namespace"
G=$(start_in "$NS_S" "$ADDR_S" "$LOGS/server.log" roslaunch --wait "$ROOT/hermes_server/launch/server.launch" \
  "config:=$LOGS/config.yaml" "output_dir:=$LOGS/server_out" "key_dir:=$LOGS/keys"); PGIDS+=("$G"); G_SERVER=$G
G=$(start_in "$NS_S" "$ADDR_S" "$LOGS/monitor_server.log" "$PY" "$ROOT/scripts/ros_netns_monitor.py" server \
  --out "$LOGS/server_state.json"); PGIDS+=("$G")
G=$(start_in "$NS_A" "$ADDR_A" "$LOGS/monitor_agent.log" "$PY" "$ROOT/scripts/ros_netns_monitor.py" agent \
  --robot "$ROBOT" --spool "$SPOOL" --out "$LOGS/agent_state.json"); PGIDS+=("$G")
for f in server_state agent_state; do
  wait_file "$LOGS/$f.json" "{" 30 || fail "monitor $f did not start: $(tail -5 "$LOGS/monitor_${f%_state}.log")"
done
# The server is up once its monitor has seen a /hermes/status (1 Hz).
wait_file "$LOGS/server_state.json" '"status": {' 60 ||
  fail "hermes_server did not publish /hermes/status: $(tail -5 "$LOGS/server.log")"

start_agent() {  # start_agent <log> <clear_spool>
  start_in "$NS_A" "$ADDR_A" "$1" roslaunch --wait "$ROOT/hermes_agent/launch/agent.launch" \
    "robot:=$ROBOT" "dataset:=$DATA" "rate:=$RATE" "start_delay:=2.0" "spool_dir:=$SPOOL" \
    "clear_spool:=$2" "config:=$LOGS/config.yaml" "key_file:=$LOGS/keys/$ROBOT.key"
}
# roslaunch itself (before any Hermes node) can fail to reach the master through the
# lossy link ("could not contact master"): that is the tool, not the agent under
# test, so a start is tried again (at most 3 times, each logged). Sets G_AGENT.
launch_agent() {  # launch_agent <run name> <log> <clear_spool>
  local try
  for try in 1 2 3; do
    G_AGENT=$(start_agent "$2" "$3"); PGIDS+=("$G_AGENT")
    log "agent $1 started (pgid $G_AGENT, clear_spool:=$3, rate $RATE, loss $LOSS % both directions, try $try)"
    for _ in $(seq 150); do  # 15 s: roslaunch has reached the master or given up by then
      grep -q "could not contact master" "$2" 2>/dev/null && break
      grep -q "process\[" "$2" 2>/dev/null && break
      sleep 0.1
    done
    grep -q "could not contact master" "$2" 2>/dev/null || return 0
    log "agent $1: roslaunch could not contact the master through the lossy link; starting it again"
    cp "$2" "${2%.log}_try$try.log"
  done
}
died() { grep -c "process has died" "$1" 2>/dev/null || true; }
at() {  # at <seconds after T0 (the first submap)>
  local now; now=$(awk -v a="$T0" -v b="$(date +%s.%N)" 'BEGIN{print b-a}')
  awk -v n="$now" -v t="$1" 'BEGIN{exit !(t > n)}' && sleep "$(awk -v n="$now" -v t="$1" 'BEGIN{print t-n}')"
  return 0
}
CREATED='sum(len(r["created"]) for r in s["runs"])'              # submaps created, all runs
PENDING='len(s["runs"][-1]["pending"]) if s["runs"] else 0'         # unacked, current run
agent_field() {  # agent_field <python expression on s (agent state)>
  "$PY" -c "import json,sys; s=json.load(open(sys.argv[1])); print($1)" "$LOGS/agent_state.json" 2>/dev/null || echo "?"
}

# wait_agent <run> <pgid> <log> <python expression on s> <regex>: up to 150 s by the clock
# until the agent state's expression matches; fails at once when the run's roslaunch
# exits or its log has a FATAL line. Returns 1 on timeout.
wait_agent() {
  local deadline=$(( $(date +%s) + 150 ))
  while (( $(date +%s) < deadline )); do
    [[ "$(agent_field "$4")" =~ $5 ]] && return 0
    kill -0 "$2" 2>/dev/null || fail "agent $1 exited: $(tail -5 "$3")"
    grep -q "FATAL" "$3" && fail "agent $1: $(grep -m2 FATAL "$3")"
    sleep 0.3
  done
  [[ "$(agent_field "$4")" =~ $5 ]]
}

T0=$(date +%s.%N)
launch_agent "run 1" "$LOGS/agent_run1.log" true; G_AGENT1=$G_AGENT
# The first submap needs the nodes up through the lossy link, a map and one window
# (47 s on a loaded 2-core CI machine): 150 s by the clock before giving up.
wait_agent "run 1" "$G_AGENT1" "$LOGS/agent_run1.log" "$CREATED" '^[1-9]' ||
  fail "agent run 1 created no submap within 150 s: $(tail -3 "$LOGS/agent_run1.log")"
T0=$(date +%s.%N)
log "agent run 1 created its first submap; the timeline starts"
at "$OUTAGE_AT"
N=$(agent_field "$CREATED")
for _ in $(seq 200); do [[ "$(agent_field "$CREATED")" != "$N" ]] && break; sleep 0.05; done
link_cut; T_CUT=$(date +%s.%N)
log "link cut (all packets dropped both ways) for $OUTAGE_S s; agent created $(agent_field "$CREATED") submap(s), $(agent_field "$PENDING") unacknowledged"
sleep "$(awk -v a="$T_CUT" -v b="$(date +%s.%N)" -v d="$OUTAGE_S" 'BEGIN{print d-(b-a)}')"
link_restore; T_BACK=$(date +%s.%N)
log "link restored after $(awk -v a="$T_CUT" -v b="$T_BACK" 'BEGIN{printf "%.1f", b-a}') s"
sleep "$KILL_AFTER"
for _ in $(seq 200); do
  [[ "$(agent_field "$PENDING")" =~ ^[1-9] ]] && break; sleep 0.05
done
CRASH_RUN1=$(died "$LOGS/agent_run1.log")
PENDING_AT_KILL=$(agent_field "$PENDING")
KILLED=$(tree "$G_AGENT1" | tr '\n' ' ')
kill -KILL $KILLED 2>/dev/null || true
log "SIGKILL to the agent's roslaunch and its nodes (pids $KILLED; spool pending before the kill: $PENDING_AT_KILL)"
for _ in $(seq 50); do [[ -z "$(alive $KILLED)" ]] && break; sleep 0.1; done
[[ -z "$(alive $KILLED)" ]] || fail "agent processes $(alive $KILLED) survived SIGKILL"
sleep "$RESTART_DELAY"
launch_agent "run 2" "$LOGS/agent_run2.log" "$RESTART_CLEAR"; G_AGENT2=$G_AGENT
# Run 2 counts from its first uplink_status. Its start goes through the lossy link
# (~20 parameter reads, topic registrations, the master's publisherUpdate to the
# monitor): run 1 needed 48 s to its first submap on a loaded CI machine, and one
# CI run saw no status of run 2 within 133 s. As for run 1: 150 s by the clock.
wait_agent "run 2" "$G_AGENT2" "$LOGS/agent_run2.log" 'len(s["runs"])' '^[2-9]' || {
  log "agent run 2 published no uplink_status within 150 s; its log ends:"
  tail -15 "$LOGS/agent_run2.log" >&2
  fail "agent run 2 never reported (logs in $LOGS)"
}
log "agent run 2 reports (uplink_status); waiting for its sequence and the spool to drain"

# Wait for run 2 to finish its sequence, its spool to drain and the server to apply it all.
"$PY" - "$LOGS/agent_state.json" "$LOGS/server_state.json" "$DRAIN_TIMEOUT" "$RATE" <<'PY' >&2 || true
import json, sys, time
agent_f, server_f, drain, rate = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4])
deadline = time.time() + 10.0 / rate + 15 + drain  # a whole sequence, startup, then drain
done_at = None
while time.time() < deadline:
    time.sleep(1)
    try:
        a, s = json.load(open(agent_f)), json.load(open(server_f))
    except (OSError, ValueError):
        continue
    runs = a.get("runs", [])
    if len(runs) < 2 or not runs[-1]["done"]:
        continue
    done_at = done_at or time.time()
    applied = sum(p.get("submaps_applied", 0) for p in (s.get("status") or {}).get("per_agent", []))
    if not runs[-1]["pending"] and applied >= sum(len(r["created"]) for r in runs):
        time.sleep(2)  # one more status of each side
        sys.exit(0)
    if time.time() - done_at > drain:
        break
print("ros_netns_delivery: timed out waiting for the spool to drain", file=sys.stderr)
sys.exit(1)
PY
RUN_TIME=$(awk -v a="$T0" -v b="$(date +%s.%N)" 'BEGIN{printf "%.1f", b-a}')
log "run finished after $RUN_TIME s; checking"

# Crashes: a node roslaunch saw die, or a process group that should still be running.
CRASHES=()
[[ "$CRASH_RUN1" -gt 0 ]] && CRASHES+=("agent run 1: $CRASH_RUN1 process(es) died before the kill")
[[ "$(died "$LOGS/agent_run2.log")" -gt 0 ]] && CRASHES+=("agent run 2: $(died "$LOGS/agent_run2.log") process(es) died")
[[ "$(died "$LOGS/server.log")" -gt 0 ]] && CRASHES+=("server: $(died "$LOGS/server.log") process(es) died")
kill -0 -- "-$G_CORE" 2>/dev/null || CRASHES+=("roscore exited")
kill -0 -- "-$G_SERVER" 2>/dev/null || CRASHES+=("server roslaunch exited")
kill -0 -- "-$G_AGENT2" 2>/dev/null || CRASHES+=("agent run 2 roslaunch exited")
grep -q "Segmentation fault\|core dumped\|terminate called" "$LOGS"/agent_run*.log "$LOGS/server.log" 2>/dev/null &&
  CRASHES+=("fatal signal or uncaught exception in a log")
# Clean server shutdown: SIGINT, it writes its results folder (metrics.json).
stop_group "$G_AGENT2" INT
stop_group "$G_SERVER" INT
for _ in $(seq 100); do kill -0 -- "-$G_SERVER" 2>/dev/null || break; sleep 0.1; done
[[ -f "$LOGS/server_out/metrics.json" ]] || CRASHES+=("server did not write its results at shutdown")
NFT_JSON="$(ip netns exec "$NS_A" nft -j list table netdev hermes_delivery 2>/dev/null || echo '{}')"
printf '%s\n' "${CRASHES[@]}" >"$LOGS/crashes.txt"

RESULT="$("$PY" - "$LOGS/agent_state.json" "$LOGS/server_state.json" "$LOGS/crashes.txt" "$NFT_JSON" \
  "$LOSS" "$OUTAGE_S" "$RUN_TIME" "$PENDING_AT_KILL" "$(elapsed)" <<'PY'
import json, sys
a = json.load(open(sys.argv[1]))
s = json.load(open(sys.argv[2]))
crashes = [l for l in open(sys.argv[3]).read().splitlines() if l.strip()]
nft = json.loads(sys.argv[4])
loss, outage_s, run_time, pending_at_kill, wall = sys.argv[5:10]
runs = a["runs"]
key = lambda r, k: "%s/%d/%d" % (r["uuid"], k[0], k[1])
accepted, dup = s["accepted"], s["duplicate"]
applied = sum(p.get("submaps_applied", 0) for p in (s.get("status") or {}).get("per_agent", []))
# Every submap a process created is one sent submap. A spool backlog found at start was
# created by an earlier process (counted there); one the monitor never saw created counts too.
created = [key(r, k) for r in runs for k in r["created"]]
replayed_unseen = {key(r, k) for r in runs for k in r["replayed"]} - set(created)
sent_total = len(created) + len(replayed_unseen)
sent = set(created) | replayed_unseen
reused = len(created) - len(set(created))  # a key created twice: the second cannot be applied
lost = sorted(sent - set(accepted))
unexpected = sorted(set(accepted) - sent)
twice = sorted(k for k, n in accepted.items() if n > 1)
per_run = []
for r in runs:
    keys = [key(r, k) for k in r["created"]]
    per_run.append({"session": r["session"], "sent": len(keys),
                    "accepted": sum(k in accepted for k in keys),
                    "duplicate_acks": sum(dup.get(k, 0) for k in keys),
                    "replayed_from_spool": len(r["replayed"]), "windows": r["windows"],
                    "sends": r["sends"], "resends": r["resends"], "done": r["done"]})
# Measured loss from the nft counters: the first rule counts, the second drops.
counters = {}
for item in nft.get("nftables", []):
    r = item.get("rule")
    if not r:
        continue
    c = [e["counter"]["packets"] for e in r["expr"] if "counter" in e]
    counters.setdefault(r["chain"], []).extend(c)
def pct(chain):
    c = counters.get(chain, [])
    return round(100.0 * c[1] / c[0], 1) if len(c) == 2 and c[0] else None
last = runs[-1] if runs else {}
cap = a.get("cap_bytes") or 0
checks = {
    "both_runs_sent": len(runs) >= 2 and all(r["sent"] > 0 for r in per_run),
    "applied_equals_sent": applied == sent_total and sent_total > 0,
    "none_lost": not lost and reused == 0,
    "none_unexpected": not unexpected,
    "no_duplicate_applied": not twice,
    "none_rejected": s["rejected"] == 0,
    "spool_drained": bool(len(runs) >= 2 and last.get("done") and not last.get("pending", [1])),
    "spool_under_cap": 0 < cap and a["max_pending_bytes"] <= cap,
    "no_crash": not crashes,
}
out = {
    "sent": sent_total, "applied": applied, "accepted_distinct": len(accepted),
    "duplicates_dropped": sum(dup.values()), "stale_dropped": s["stale"],
    "accepted_twice": len(twice), "lost": len(lost) + reused, "lost_keys": lost[:10],
    "keys_reused": reused,
    "unexpected": len(unexpected), "rejected": s["rejected"],
    "runs": per_run, "pending_at_kill": int(pending_at_kill) if pending_at_kill.isdigit() else None,
    "spool_max_pending_bytes": a["max_pending_bytes"], "spool_max_file_bytes": a["max_file_bytes"],
    "spool_max_disk_bytes": a["max_disk_bytes"], "spool_cap_bytes": cap,
    "spool_final_pending": len(last.get("pending", [])),
    "loss_pct": float(loss), "measured_loss_pct_in": pct("in"), "measured_loss_pct_out": pct("out"),
    "outage_s": float(outage_s), "run_time_s": float(run_time), "wall_time_s": float(wall),
    "crashes": crashes, "checks": checks, "pass": all(checks.values()),
}
print(json.dumps(out))
PY
)" || fail "could not evaluate the run (state files in $LOGS)"
echo "$RESULT"
[[ -z "$JSON" ]] || echo "$RESULT" >"$JSON"
if [[ "$RESULT" == *'"pass": true'* ]]; then exit 0; fi
for f in agent_run2 monitor_agent server; do  # the CI output is all a clean clone keeps
  echo "ros_netns_delivery: the last lines of $f.log:" >&2
  tail -8 "$LOGS/$f.log" >&2 2>/dev/null || true
done
KEEP_LOGS=1
exit 1
