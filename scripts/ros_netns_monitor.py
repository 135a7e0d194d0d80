#!/usr/bin/python3
"""Observer for scripts/ros_netns_delivery.sh (one per network namespace).

  ros_netns_monitor.py agent  --robot agent0 --spool DIR --out STATE.json
      (agent namespace, next to the agent, so the link does not hide anything)
      /<robot>/uplink_status: union of the submaps every agent process created
      (and found pending in the spool at start), spool pending / file bytes and
      cap; plus the spool folder's size on disk, sampled every 0.2 s.
  ros_netns_monitor.py server --out STATE.json
      (server namespace, next to hermes_server_node)
      /hermes/submap_ack: ACCEPTED / DUPLICATE (incl. stale) / REJECTED per
      (uuid, session, seq); /hermes/status: the server's metrics JSON.

The state is rewritten (atomically) five times a second and on shutdown, so
the caller can read it at any time and after SIGINT.
"""
import argparse
import json
import os
import threading

import rospy
from std_msgs.msg import String


def write_state(path, state):
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        json.dump(state, f)
    os.replace(tmp, path)


def dir_bytes(path):
    total = 0
    try:
        for name in os.listdir(path):
            try:
                total += os.path.getsize(os.path.join(path, name))
            except OSError:
                pass
    except OSError:
        pass
    return total


class AgentMonitor:
    """One entry per agent process (pid), in order of appearance: a restarted agent may
    reuse (session, seq) keys (e.g. after clear_spool), so runs are not merged by key."""

    def __init__(self, robot, spool):
        self.lock = threading.Lock()
        self.spool = spool
        self.s = {"runs": [], "last": None, "statuses": 0, "max_pending_bytes": 0,
                  "max_file_bytes": 0, "max_disk_bytes": 0, "cap_bytes": None}
        rospy.Subscriber("/%s/uplink_status" % robot, String, self.on_status, queue_size=100)

    def on_status(self, msg):
        j = json.loads(msg.data)
        with self.lock:
            s = self.s
            s["statuses"] += 1
            run = next((r for r in s["runs"] if r["pid"] == j["pid"]), None)
            if run is None:
                run = {"pid": j["pid"], "created": [], "replayed": []}
                s["runs"].append(run)
            for field in ("created", "replayed"):  # a latched status can be missed, never shrinks
                for key in j[field]:
                    if key not in run[field]:
                        run[field].append(key)
            run.update({"uuid": j["uuid"], "session": j["session"], "windows": j["windows"],
                        "sends": j["sends"], "resends": j["resends"], "acked": j["acked"],
                        "pending": j["pending"], "done": j["done"]})
            s["max_pending_bytes"] = max(s["max_pending_bytes"], j["spool_pending_bytes"])
            s["max_file_bytes"] = max(s["max_file_bytes"], j["spool_file_bytes"])
            s["cap_bytes"] = j["spool_cap_bytes"]
            s["last"] = j

    def sample(self):
        b = dir_bytes(self.spool)
        with self.lock:
            self.s["max_disk_bytes"] = max(self.s["max_disk_bytes"], b)
            self.s["disk_bytes"] = b
            return json.loads(json.dumps(self.s))


class ServerMonitor:
    def __init__(self):
        from hermes_msgs.msg import SubmapAck
        self.SubmapAck = SubmapAck
        self.lock = threading.Lock()
        self.s = {"accepted": {}, "duplicate": {}, "stale": 0, "rejected": 0, "rejected_reasons": [],
                  "status": None, "status_count": 0}
        rospy.Subscriber("/hermes/submap_ack", SubmapAck, self.on_ack, queue_size=1000)
        rospy.Subscriber("/hermes/status", String, self.on_status, queue_size=10)

    def on_ack(self, a):
        key = "%s/%d/%d" % (a.agent_uuid, a.session, a.seq)
        with self.lock:
            if a.status == self.SubmapAck.ACCEPTED:
                self.s["accepted"][key] = self.s["accepted"].get(key, 0) + 1
            elif a.status == self.SubmapAck.DUPLICATE:
                self.s["duplicate"][key] = self.s["duplicate"].get(key, 0) + 1
                if "superseded" in a.reason:
                    self.s["stale"] += 1
            else:
                self.s["rejected"] += 1
                if len(self.s["rejected_reasons"]) < 5:
                    self.s["rejected_reasons"].append(a.reason)

    def on_status(self, m):
        with self.lock:
            self.s["status"] = json.loads(m.data)
            self.s["status_count"] += 1

    def sample(self):
        with self.lock:
            return json.loads(json.dumps(self.s))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("role", choices=["agent", "server"])
    ap.add_argument("--robot", default="agent0")
    ap.add_argument("--spool", default="")
    ap.add_argument("--out", required=True)
    args = ap.parse_args(rospy.myargv()[1:])
    rospy.init_node("hermes_delivery_monitor_" + args.role, disable_signals=False)
    mon = AgentMonitor(args.robot, args.spool) if args.role == "agent" else ServerMonitor()
    rate = rospy.Rate(5)
    while not rospy.is_shutdown():
        write_state(args.out, mon.sample())
        try:
            rate.sleep()
        except rospy.ROSInterruptException:
            break
    write_state(args.out, mon.sample())


if __name__ == "__main__":
    main()
