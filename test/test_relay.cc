// rostest (relay.test): agent1 out of the server's reach (relay_via:=agent0)
// and its relay agent0 (relay_for:=agent1), both DatasetPlayer + Agent
// nodelets, and hermes_server_node, over real ROS topics. Checks that agent1's
// submaps reach the server only through agent0 (agent1 publishes nothing to
// /hermes/submap and listens to no /hermes topic; every one of its submaps was
// offered on /agent0/relay/submap, held, forwarded), that every submap of both
// robots was applied exactly once, that both maps merged, and that the
// acknowledgements came back to the origin: hop acknowledgements, then the
// server's through the relay, until agent1's spool is empty.
// With ~kill_relay (relay_restart.test) the server starts late: once agent1's
// submaps are all held by agent0 and none reached the server, the test
// SIGKILLs agent0's nodelet manager; roslaunch starts it again on the same
// spool folders, and agent1's submaps must then come out of the relay's spool
// (the restarted relay stores none of them again), applied exactly once.
#include <gtest/gtest.h>
#include <hermes_msgs/AgentHeartbeat.h>
#include <hermes_msgs/EncodedSubmap.h>
#include <hermes_msgs/GlobalPose.h>
#include <hermes_msgs/SubmapAck.h>
#include <ros/ros.h>
#include <std_msgs/Empty.h>
#include <std_msgs/String.h>

#include <signal.h>

#include <filesystem>
#include <map>
#include <mutex>
#include <set>
#include <tuple>

#include <nlohmann/json.hpp>

#include "hermes/core/map_types.h"
#include "rostest_support.h"

namespace {

using hermes_tests::nodePid;
using hermes_tests::nodesOf;
using Key = std::tuple<std::string, std::uint32_t, std::uint64_t>;

struct Observed {
  std::mutex mu;
  std::map<Key, int> to_server, offered, held, passed_back, accepted, duplicate;
  int rejected = 0, done = 0;
  std::set<std::string> global_via_relay, heartbeats;
  std::string status;
  std::map<std::string, nlohmann::json> uplink;
};

Key keyOf(const std::string& uuid, std::uint32_t session, std::uint64_t seq) { return Key{uuid, session, seq}; }

bool anyIn(const std::set<std::string>& nodes, const std::string& ns) {
  for (const std::string& n : nodes)
    if (n.rfind(ns, 0) == 0) return true;
  return false;
}

/// The server acknowledged submap k: its ACCEPTED ack, or a DUPLICATE one, or the
/// relay passing the server's ack back. The server node starts late in these
/// launches and accepts the relayed submaps at once, often before this test's
/// subscriber has connected to its new publisher, so an ACCEPTED ack can be
/// missed here (a CI run saw none for agent1 while its map merged). Applied
/// exactly once is checked on the server's own count (expectMergedAndApplied).
bool acknowledged(const Observed& o, const Key& k) {
  return o.accepted.count(k) || o.duplicate.count(k) || o.passed_back.count(k);
}

}  // namespace

TEST(Relay, RelayedRobotReachesTheServerOnlyThroughItsRelayExactlyOnce) {
  ros::NodeHandle nh, pnh("~");
  bool kill_relay = false;
  pnh.param("kill_relay", kill_relay, false);
  int killed_pid = 0;
  std::size_t accepted_before_kill = 0;
  Observed o;
  const std::string uuid1 = hermes::toString(hermes::agentUuid("agent1"));
  std::vector<ros::Subscriber> subs;
  auto count = [&o](std::map<Key, int>& m) {
    return [&o, &m](const hermes_msgs::EncodedSubmapConstPtr& s) {
      std::lock_guard<std::mutex> l(o.mu);
      ++m[keyOf(s->agent_uuid, s->session, s->seq)];
    };
  };
  auto countAck = [&o](std::map<Key, int>& m) {
    return [&o, &m](const hermes_msgs::SubmapAckConstPtr& a) {
      std::lock_guard<std::mutex> l(o.mu);
      ++m[keyOf(a->agent_uuid, a->session, a->seq)];
    };
  };
  subs.push_back(nh.subscribe<hermes_msgs::EncodedSubmap>("/hermes/submap", 100, count(o.to_server)));
  subs.push_back(nh.subscribe<hermes_msgs::EncodedSubmap>("/agent0/relay/submap", 100, count(o.offered)));
  subs.push_back(nh.subscribe<hermes_msgs::SubmapAck>("/agent0/relay/agent1/held", 100, countAck(o.held)));
  subs.push_back(nh.subscribe<hermes_msgs::SubmapAck>("/agent0/relay/agent1/submap_ack", 100, countAck(o.passed_back)));
  subs.push_back(nh.subscribe<hermes_msgs::SubmapAck>(
      "/hermes/submap_ack", 100, [&](const hermes_msgs::SubmapAckConstPtr& a) {
        std::lock_guard<std::mutex> l(o.mu);
        const Key k = keyOf(a->agent_uuid, a->session, a->seq);
        if (a->status == hermes_msgs::SubmapAck::ACCEPTED) ++o.accepted[k];
        if (a->status == hermes_msgs::SubmapAck::DUPLICATE) ++o.duplicate[k];
        if (a->status == hermes_msgs::SubmapAck::REJECTED) ++o.rejected;
      }));
  subs.push_back(nh.subscribe<hermes_msgs::GlobalPose>(
      "/agent0/relay/agent1/global_pose", 20, [&](const hermes_msgs::GlobalPoseConstPtr& g) {
        std::lock_guard<std::mutex> l(o.mu);
        o.global_via_relay.insert(g->agent_uuid);
      }));
  subs.push_back(nh.subscribe<hermes_msgs::AgentHeartbeat>(
      "/hermes/heartbeat", 20, [&](const hermes_msgs::AgentHeartbeatConstPtr& h) {
        std::lock_guard<std::mutex> l(o.mu);
        o.heartbeats.insert(h->name);
      }));
  subs.push_back(nh.subscribe<std_msgs::String>("/hermes/status", 5, [&](const std_msgs::StringConstPtr& s) {
    std::lock_guard<std::mutex> l(o.mu);
    o.status = s->data;
  }));
  for (const std::string robot : {"agent0", "agent1"}) {
    subs.push_back(nh.subscribe<std_msgs::String>(
        "/" + robot + "/uplink_status", 5, [&o, robot](const std_msgs::StringConstPtr& m) {
          auto j = nlohmann::json::parse(m->data, nullptr, false);
          std::lock_guard<std::mutex> l(o.mu);
          if (j.is_object()) o.uplink[robot] = j;
        }));
    subs.push_back(nh.subscribe<std_msgs::Empty>("/" + robot + "/done", 1, [&](const std_msgs::EmptyConstPtr&) {
      std::lock_guard<std::mutex> l(o.mu);
      ++o.done;
    }));
  }
  ros::AsyncSpinner spinner(2);
  spinner.start();

  // The wiring, once both agents are up: agent1 talks to agent0's relay topics only.
  const ros::WallTime up_deadline = ros::WallTime::now() + ros::WallDuration(30.0);
  while (ros::WallTime::now() < up_deadline &&
         !(anyIn(nodesOf("/agent0/relay/submap", true), "/agent1/") &&
           anyIn(nodesOf("/agent0/relay/submap", false), "/agent0/")))
    ros::WallDuration(0.2).sleep();
  EXPECT_TRUE(anyIn(nodesOf("/agent0/relay/submap", true), "/agent1/")) << "agent1 does not offer to agent0";
  EXPECT_TRUE(anyIn(nodesOf("/agent0/relay/submap", false), "/agent0/")) << "agent0 does not listen";
  EXPECT_TRUE(anyIn(nodesOf("/hermes/submap", true), "/agent0/")) << "the relay does not reach the server";
  for (const std::string topic : {"/hermes/submap", "/hermes/heartbeat"})
    EXPECT_FALSE(anyIn(nodesOf(topic, true), "/agent1/")) << "agent1 publishes " << topic << " directly";
  for (const std::string topic : {"/hermes/submap_ack", "/hermes/global_pose"})
    EXPECT_FALSE(anyIn(nodesOf(topic, false), "/agent1/")) << "agent1 listens to " << topic << " directly";

  // Both sequences end; then every submap is acknowledged, agent1's spool is
  // empty (the server's acknowledgements came back through the relay) and the
  // two maps are merged.
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(kill_relay ? 200.0 : 110.0);
  ros::WallTime settled;
  bool finished = false;
  while (ros::WallTime::now() < deadline && !finished) {
    ros::WallDuration(0.5).sleep();
    std::lock_guard<std::mutex> l(o.mu);
    if (kill_relay && killed_pid == 0) {  // agent1 done, all of its submaps held by agent0
      const auto u1 = o.uplink.find("agent1");
      if (u1 == o.uplink.end() || !u1->second.value("done", false)) continue;
      const auto created = u1->second.value("created", nlohmann::json::array());
      std::size_t held = 0, accepted = 0;
      for (const auto& [k, n] : o.held) held += std::get<0>(k) == uuid1;
      for (const auto& [k, n] : o.accepted) accepted += std::get<0>(k) == uuid1;
      if (created.empty() || held < created.size()) continue;
      accepted_before_kill = accepted;
      killed_pid = nodePid("/agent0/manager");
      ASSERT_GT(killed_pid, 0) << "cannot find agent0's nodelet manager";
      ASSERT_EQ(::kill(killed_pid, SIGKILL), 0);
      std::printf("killed the relay (pid %d) holding agent1's %zu submaps, %zu accepted so far\n", killed_pid,
                  held, accepted);
      o.uplink.erase("agent0");  // wait for the restarted relay's own status
      continue;
    }
    if (o.done < 2 || o.uplink.size() < 2) continue;
    bool ok = !o.to_server.empty();
    for (const auto& [k, n] : o.to_server) ok = ok && acknowledged(o, k);
    for (const auto& [robot, j] : o.uplink)  // a restarted relay may carry its windows past the end: none made
      ok = ok && j.value("done", false) && j.contains("pending") && j["pending"].empty() &&
           (!j.value("created", nlohmann::json::array()).empty() || (kill_relay && robot == "agent0"));
    const auto st = nlohmann::json::parse(o.status.empty() ? "{}" : o.status, nullptr, false);
    ok = ok && st.is_object() && st.value("agents_merged", 0) == 2;
    if (!ok) {
      settled = ros::WallTime();
      continue;
    }
    if (settled.isZero()) settled = ros::WallTime::now();
    finished = ros::WallTime::now() - settled > ros::WallDuration(2.0);
  }
  spinner.stop();
  std::lock_guard<std::mutex> l(o.mu);
  std::printf("to the server %zu distinct submaps, offered to the relay %zu, held %zu, passed back %zu, status %s\n",
              o.to_server.size(), o.offered.size(), o.held.size(), o.passed_back.size(), o.status.c_str());
  ASSERT_GE(o.done, 2) << "not every player finished";
  if (kill_relay) {
    ASSERT_GT(killed_pid, 0) << "the relay was never killed";
    EXPECT_EQ(accepted_before_kill, 0u) << "the server took agent1's submaps before the relay was killed";
    EXPECT_NE(nodePid("/agent0/manager"), killed_pid) << "the relay was not started again";
    std::string spool;  // this run's folders (the launch file names them anew each run)
    if (ros::param::get("/agent0/agent/spool_dir", spool) && !spool.empty()) {
      std::error_code ec;
      std::filesystem::remove_all(std::filesystem::path(spool).parent_path(), ec);
    }
  }
  ASSERT_EQ(o.uplink.size(), 2u);
  EXPECT_EQ(o.rejected, 0);

  // agent1: every submap it made went to the relay, was held, forwarded and
  // acknowledged by the server once, and the acknowledgement came back.
  const nlohmann::json& u1 = o.uplink["agent1"];
  std::printf("agent1 uplink: relay_via %s, hop_acks %d, handed_over %d, pending %s\n",
              u1.value("relay_via", "").c_str(), u1.value("hop_acks", 0), u1.value("handed_over", -1),
              u1.value("pending", nlohmann::json()).dump().c_str());
  EXPECT_EQ(u1.value("relay_via", ""), "agent0");
  std::set<Key> created1;
  for (const auto& key : u1.value("created", nlohmann::json::array()))
    created1.insert(keyOf(uuid1, key[0].get<std::uint32_t>(), key[1].get<std::uint64_t>()));
  ASSERT_FALSE(created1.empty()) << "agent1 made no submap";
  for (const Key& k : created1) {
    const std::string what = "agent1 seq " + std::to_string(std::get<2>(k));
    EXPECT_TRUE(o.offered.count(k)) << what << " never offered to the relay";
    EXPECT_TRUE(o.held.count(k)) << what << " never held by the relay";
    EXPECT_TRUE(o.to_server.count(k)) << what << " never forwarded to the server";
    EXPECT_TRUE(acknowledged(o, k)) << what << " never acknowledged by the server";
    EXPECT_LE(o.accepted.count(k) ? o.accepted.at(k) : 0, 1) << what << " accepted twice";
    EXPECT_TRUE(o.passed_back.count(k)) << what << ": the server's acknowledgement not passed back";
  }
  EXPECT_TRUE(u1.contains("pending") && u1["pending"].empty()) << "agent1's spool holds unacknowledged submaps";
  EXPECT_GE(u1.value("hop_acks", 0), static_cast<int>(created1.size()));
  EXPECT_EQ(u1.value("handed_over", -1), 0) << "submaps still waiting for the server's acknowledgement";
  for (const auto& [k, n] : o.offered) EXPECT_EQ(std::get<0>(k), uuid1) << "someone else offered to the relay";

  // The relay's account of it.
  const nlohmann::json& u0 = o.uplink["agent0"];
  ASSERT_TRUE(u0.contains("relay_for") && u0["relay_for"].contains("agent1")) << u0.dump();
  const nlohmann::json& r = u0["relay_for"]["agent1"];
  std::printf("agent0 relays agent1: %s\n", r.dump().c_str());
  // A restarted relay forwards them from its spool: agent1's offers again are copies it holds.
  EXPECT_EQ(r.value("stored", 0), kill_relay ? 0 : static_cast<int>(created1.size()));
  EXPECT_EQ(r.value("server_acked", 0), static_cast<int>(created1.size()));
  EXPECT_EQ(r.value("pending", -1), 0);
  EXPECT_GE(r.value("rate_kBps", 0.0), 125.0 - 1e-6) << "below relay.min_mbitps";

  // Both robots, every submap applied exactly once; both maps merged.
  std::set<std::string> robots;
  for (const auto& [k, n] : o.to_server) {
    robots.insert(std::get<0>(k));
    EXPECT_TRUE(acknowledged(o, k)) << std::get<0>(k) << " seq " << std::get<2>(k) << " never acknowledged";
    EXPECT_LE(o.accepted.count(k) ? o.accepted.at(k) : 0, 1)
        << std::get<0>(k) << " seq " << std::get<2>(k) << " accepted twice";
  }
  EXPECT_EQ(robots.size(), 2u);
  hermes_tests::expectMergedAndApplied(o.status, 2, o.to_server.size());
  EXPECT_TRUE(o.heartbeats.count("agent1")) << "agent1's heartbeat not passed on to the server";
  EXPECT_TRUE(o.global_via_relay.count(uuid1)) << "agent1's global pose not passed on by the relay";
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_relay");
  return RUN_ALL_TESTS();
}
