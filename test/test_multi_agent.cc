// rostest: three agents (DatasetPlayer + Agent nodelets) and hermes_server_node
// over real ROS topics on rendered data. Checks that every submap an agent sent
// was accepted exactly once, that all three maps merged into one frame, and the
// merged keyframe paths against the rendered ground truth; with authentication
// on, as the launch files have it, and unauthenticated frames refused.
// With ~kill_server_after_accepted N (server_restart.test) the test kills the
// server node with SIGKILL once N submaps were accepted; roslaunch respawns it
// and it resumes from its checkpoint directory. A submap accepted just before
// the kill may then be acknowledged as a duplicate only (its ack was lost with
// the process), so each is acknowledged, accepted at most once, and the server
// reports every one applied.
// With ~transport mqtt (multi_agent_mqtt.test) the nodes talk through a real
// mosquitto that this test starts on ~mqtt_port, and the test observes the
// hermes/+/submap, /ack and /heartbeat topics through the broker instead of the
// ROS topics. With ~restart_broker_after_accepted N it SIGKILLs the broker once N
// submaps were accepted and starts it again 2 s later; submaps and acks of that
// gap are not all seen by the observer, so, as with the server kill, each
// submap the agents created (their uplink_status) must be acknowledged (their
// spools drain), accepted at most once, and the server reports every one applied.
#include <gtest/gtest.h>
#include <hermes_msgs/AgentHeartbeat.h>
#include <hermes_msgs/EncodedSubmap.h>
#include <hermes_msgs/GlobalPose.h>
#include <hermes_msgs/MapDown.h>
#include <hermes_msgs/MapDownAck.h>
#include <hermes_msgs/SubmapAck.h>
#include <nav_msgs/Odometry.h>
#include <nav_msgs/Path.h>
#include <ros/master.h>
#include <ros/network.h>
#include <ros/ros.h>
#include <std_msgs/Empty.h>
#include <std_msgs/String.h>

#include <signal.h>
#include <xmlrpcpp/XmlRpc.h>

#include <filesystem>
#include <map>
#include <mutex>
#include <set>
#include <tuple>

#include <nlohmann/json.hpp>

#include "hermes/core/dataset.h"
#include "hermes/core/evaluation.h"
#include "hermes/core/frame_auth.h"
#include "hermes/core/wire_format.h"
#include "hermes/core/wire_synthetic.h"
#include "hermes/transport/mqtt_client.h"
#include "hermes/transport/mqtt_messages.h"
#include "mosquitto_broker.h"
#include "rostest_support.h"

namespace {

using hermes_tests::nodePid;
using Key = std::tuple<std::string, std::uint32_t, std::uint64_t>;
const std::map<std::string, std::string> kSequence = {
    {"agent0", "MH_01_easy"}, {"agent1", "MH_02_easy"}, {"agent2", "MH_03_medium"}};

struct Observed {
  std::mutex mu;
  std::map<Key, int> sent, accepted, duplicate;
  int duplicates = 0, rejected = 0, done = 0;
  std::map<std::string, std::string> name_of_uuid;
  std::map<std::uint32_t, std::string> uuid_of_robot;
  std::map<std::uint32_t, nav_msgs::Path> paths;
  std::map<std::string, hermes::Trajectory> odom;  ///< per robot, body poses (odometry frame)
  std::string status;
  std::map<std::string, nlohmann::json> uplink;  ///< per robot, its last uplink_status
  std::map<std::string, hermes_msgs::GlobalPose> global;  ///< per uuid, the latest world <- odom
  /// The downlink: per uuid, the (epoch, seq) packets sent and acknowledged, bytes sent.
  std::map<std::string, std::set<std::pair<std::uint64_t, std::uint64_t>>> down_sent, down_acked;
  std::map<std::string, std::size_t> down_bytes;
};

/// MQTT mode: the broker this test runs (kept for every test of the process) and
/// the parameters the nodes were given.
std::unique_ptr<hermes::transport::test::MosquittoBroker> g_broker;
hermes::transport::MqttParams g_mqtt;

/// Starts the broker on ~mqtt_port once; false when there is no mosquitto binary.
bool startBroker(int port) {
  if (g_broker) return true;
  if (hermes::transport::test::MosquittoBroker::binary().empty()) return false;
  g_broker = std::make_unique<hermes::transport::test::MosquittoBroker>(
      "/tmp/hermes_rostest_mqtt_broker_" + std::to_string(port), hermes::transport::test::BrokerOptions{}, port);
  EXPECT_TRUE(g_broker->start()) << g_broker->error();
  g_mqtt = hermes::transport::test::testMqttParams(port);
  return true;
}

/// An observer client subscribed to every robot's channels.
std::unique_ptr<hermes::transport::MqttClient> observer(const std::string& id) {
  using hermes::transport::MqttChannel;
  auto c = hermes::transport::MqttClient::create(
      g_mqtt, id,
      {{hermes::transport::mqttTopicAllAgents(MqttChannel::kSubmap), 2},
       {hermes::transport::mqttTopicAllAgents(MqttChannel::kAck), 2},
       {hermes::transport::mqttTopicAllAgents(MqttChannel::kHeartbeat), 0}});
  EXPECT_TRUE(c.ok()) << c.error();
  if (!c.ok()) return nullptr;
  (*c)->start();
  EXPECT_TRUE((*c)->waitConnected(5)) << (*c)->lastError();
  return std::move(*c);
}

/// A small valid frame claiming to be `robot`'s seq `seq`, tagged with `key` if given.
std::vector<std::uint8_t> forgedFrame(const std::string& robot, std::uint64_t seq, const hermes::FrameKey* key) {
  hermes::SyntheticSubmapOptions opt;
  opt.keyframes = 2;
  opt.keypoints_per_keyframe = 30;
  opt.landmarks = 20;
  hermes::Submap s = hermes::makeSyntheticSubmap(opt);
  s.header.agent = hermes::agentUuid(robot);
  s.header.seq = seq;
  auto f = hermes::encodeSubmap(s);
  EXPECT_TRUE(f.ok());
  if (key && f.ok()) f = hermes::signFrame(*f, *key);
  return f.ok() ? *f : std::vector<std::uint8_t>();
}

/// Records what the observer saw, as the ROS subscriptions do.
void observeMqtt(hermes::transport::MqttClient& client, Observed& o) {
  using namespace hermes::transport;
  for (MqttEvent& e : client.drain()) {
    if (e.kind != MqttEvent::Kind::kMessage) continue;
    auto topic = parseMqttTopic(e.topic);
    if (!topic) continue;
    std::lock_guard<std::mutex> l(o.mu);
    if (topic->channel == MqttChannel::kSubmap) {
      auto h = hermes::peekFrame(e.payload.data(), e.payload.size());
      if (h) ++o.sent[Key{hermes::toString(h->routing.agent), h->routing.session, h->routing.seq}];
    } else if (topic->channel == MqttChannel::kAck) {
      auto a = decodeAck(e.payload.data(), e.payload.size());
      if (!a) continue;
      const Key k{hermes::toString(a->agent), a->session, a->seq};
      if (a->status == AckStatus::kAccepted) ++o.accepted[k];
      if (a->status == AckStatus::kDuplicate) {
        ++o.duplicates;
        ++o.duplicate[k];
      }
      if (a->status == AckStatus::kRejected) ++o.rejected;
      o.uuid_of_robot[a->robot_id] = hermes::toString(a->agent);
    } else {
      auto hb = decodeHeartbeat(e.payload.data(), e.payload.size());
      if (hb) o.name_of_uuid[hermes::toString(hb->agent)] = hb->name;
    }
  }
}

hermes::Trajectory toTrajectory(const nav_msgs::Path& path) {
  hermes::Trajectory t;
  for (const auto& p : path.poses) {
    const auto& q = p.pose.orientation;
    const hermes::SE3 T(hermes::Quat(q.w, q.x, q.y, q.z).normalized(),
                        hermes::Vec3(p.pose.position.x, p.pose.position.y, p.pose.position.z));
    t.push_back(hermes::StampedPose{p.header.stamp.toSec(), T});
  }
  return t;
}

}  // namespace

TEST(MultiAgent, ThreeAgentsMergeOverRosTopicsExactlyOnce) {
  ros::NodeHandle nh, pnh("~");
  std::string data;
  ASSERT_TRUE(pnh.getParam("data", data)) << "~data (rendered folder) is required";
  Observed o;
  std::string transport = "ros";
  pnh.param("transport", transport, transport);
  const bool mqtt = transport == "mqtt";
  int mqtt_port = 0, restart_broker_after = 0;
  pnh.param("mqtt_port", mqtt_port, 0);
  pnh.param("restart_broker_after_accepted", restart_broker_after, 0);
  std::unique_ptr<hermes::transport::MqttClient> watcher;
  if (mqtt) {
    if (!startBroker(mqtt_port)) GTEST_SKIP() << "no mosquitto binary (apt-get install mosquitto)";
    watcher = observer("hermes-rostest-observer");
    ASSERT_TRUE(watcher);
  }
  std::vector<ros::Subscriber> subs;
  for (const auto& [robot, seq] : kSequence)
    subs.push_back(nh.subscribe<std_msgs::String>(
        "/" + robot + "/uplink_status", 5, [&o, robot = robot](const std_msgs::StringConstPtr& m) {
          auto j = nlohmann::json::parse(m->data, nullptr, false);
          std::lock_guard<std::mutex> l(o.mu);
          if (j.is_object()) o.uplink[robot] = j;
        }));
  if (!mqtt) {
  subs.push_back(nh.subscribe<hermes_msgs::EncodedSubmap>(
      "/hermes/submap", 100, [&](const hermes_msgs::EncodedSubmapConstPtr& m) {
        std::lock_guard<std::mutex> l(o.mu);
        ++o.sent[Key{m->agent_uuid, m->session, m->seq}];
      }));
  subs.push_back(nh.subscribe<hermes_msgs::SubmapAck>(
      "/hermes/submap_ack", 100, [&](const hermes_msgs::SubmapAckConstPtr& a) {
        std::lock_guard<std::mutex> l(o.mu);
        if (a->status == hermes_msgs::SubmapAck::ACCEPTED) ++o.accepted[Key{a->agent_uuid, a->session, a->seq}];
        if (a->status == hermes_msgs::SubmapAck::DUPLICATE) {
          ++o.duplicates;
          ++o.duplicate[Key{a->agent_uuid, a->session, a->seq}];
        }
        if (a->status == hermes_msgs::SubmapAck::REJECTED) ++o.rejected;
        o.uuid_of_robot[a->robot_id] = a->agent_uuid;
      }));
  subs.push_back(nh.subscribe<hermes_msgs::GlobalPose>(
      "/hermes/global_pose", 100, [&](const hermes_msgs::GlobalPoseConstPtr& g) {
        std::lock_guard<std::mutex> l(o.mu);
        o.global[g->agent_uuid] = *g;
      }));
  subs.push_back(nh.subscribe<hermes_msgs::MapDown>(
      "/hermes/map_down", 100, [&](const hermes_msgs::MapDownConstPtr& m) {
        std::lock_guard<std::mutex> l(o.mu);
        o.down_sent[m->agent_uuid].insert({m->epoch, m->seq});
        o.down_bytes[m->agent_uuid] += m->data.size();
      }));
  subs.push_back(nh.subscribe<hermes_msgs::MapDownAck>(
      "/hermes/map_down_ack", 100, [&](const hermes_msgs::MapDownAckConstPtr& a) {
        std::lock_guard<std::mutex> l(o.mu);
        o.down_acked[a->agent_uuid].insert({a->epoch, a->seq});
      }));
  subs.push_back(nh.subscribe<hermes_msgs::AgentHeartbeat>(
      "/hermes/heartbeat", 10, [&](const hermes_msgs::AgentHeartbeatConstPtr& h) {
        std::lock_guard<std::mutex> l(o.mu);
        o.name_of_uuid[h->agent_uuid] = h->name;
      }));
  }
  subs.push_back(nh.subscribe<std_msgs::String>("/hermes/status", 5, [&](const std_msgs::StringConstPtr& s) {
    std::lock_guard<std::mutex> l(o.mu);
    o.status = s->data;
  }));
  for (const auto& [robot, seq] : kSequence)
    subs.push_back(nh.subscribe<nav_msgs::Odometry>(
        "/" + robot + "/odom", 100, [&o, robot = robot](const nav_msgs::OdometryConstPtr& m) {
          const auto& q = m->pose.pose.orientation;
          const auto& p = m->pose.pose.position;
          std::lock_guard<std::mutex> l(o.mu);
          o.odom[robot].push_back(hermes::StampedPose{
              m->header.stamp.toSec(),
              hermes::SE3(hermes::Quat(q.w, q.x, q.y, q.z), hermes::Vec3(p.x, p.y, p.z))});
        }));
  for (const auto& [robot, seq] : kSequence)
    subs.push_back(nh.subscribe<std_msgs::Empty>("/" + robot + "/done", 1, [&](const std_msgs::EmptyConstPtr&) {
      std::lock_guard<std::mutex> l(o.mu);
      ++o.done;
    }));
  for (std::uint32_t r = 0; r < 3; ++r)
    subs.push_back(nh.subscribe<nav_msgs::Path>(
        "/hermes/path/" + std::to_string(r), 1, [&o, r](const nav_msgs::PathConstPtr& p) {
          std::lock_guard<std::mutex> l(o.mu);
          o.paths[r] = *p;
        }));
  int kill_after = 0;
  pnh.param("kill_server_after_accepted", kill_after, 0);
  int killed_pid = 0;
  ros::WallTime broker_killed;
  bool broker_restarted = false;
  std::size_t accepted_at_broker_kill = 0;
  ros::AsyncSpinner spinner(2);
  spinner.start();

  // Wait for the sequences to end, then for every submap to be acknowledged and
  // the server to report three merged agents.
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(240.0);
  ros::WallTime all_done;
  bool finished = false;
  while (ros::WallTime::now() < deadline && !finished) {
    ros::WallDuration(0.5).sleep();
    if (watcher) observeMqtt(*watcher, o);
    std::lock_guard<std::mutex> l(o.mu);
    if (restart_broker_after > 0 && broker_killed.isZero() &&
        static_cast<int>(o.accepted.size()) >= restart_broker_after) {
      accepted_at_broker_kill = o.accepted.size();
      g_broker->kill();
      broker_killed = ros::WallTime::now();
      std::printf("killed the broker after %zu accepted submaps, %d players done\n", o.accepted.size(), o.done);
    }
    if (!broker_killed.isZero() && !broker_restarted && ros::WallTime::now() - broker_killed > ros::WallDuration(2.0)) {
      ASSERT_TRUE(g_broker->start()) << g_broker->error();
      broker_restarted = true;
      o.status.clear();  // wait for a status after the restart
    }
    if (kill_after > 0 && killed_pid == 0 && static_cast<int>(o.accepted.size()) >= kill_after) {
      killed_pid = nodePid("/hermes_server");
      ASSERT_GT(killed_pid, 0) << "cannot find the server's process";
      ASSERT_EQ(::kill(killed_pid, SIGKILL), 0);
      std::printf("killed the server (pid %d) after %zu accepted submaps, %d players done\n",
                  killed_pid, o.accepted.size(), o.done);
      o.status.clear();  // wait for the respawned server's own status
    }
    if (o.done < 3) continue;
    if (all_done.isZero()) all_done = ros::WallTime::now();
    bool all_acked = !o.sent.empty();
    if (restart_broker_after > 0) {  // the agents' spools say it: nothing left unacknowledged
      all_acked = broker_restarted && o.uplink.size() == 3;
      for (const auto& [robot, j] : o.uplink) {
        all_acked = all_acked && j.value("done", false) && j.contains("pending") && j["pending"].empty();
        for (const auto& key : j.value("created", nlohmann::json::array()))
          o.sent.emplace(Key{j.value("uuid", ""), key[0].get<std::uint32_t>(), key[1].get<std::uint64_t>()}, 0);
      }
    } else {
      for (const auto& [k, n] : o.sent)
        all_acked = all_acked && (o.accepted.count(k) || (killed_pid && o.duplicate.count(k)));
    }
    const auto j = nlohmann::json::parse(o.status.empty() ? "{}" : o.status, nullptr, false);
    const bool merged = j.is_object() && j.value("agents_merged", 0) == 3;
    finished = all_acked && merged && o.paths.size() == 3 && (mqtt || o.global.size() == 3) &&
               ros::WallTime::now() - all_done > ros::WallDuration(5.0);
  }
  spinner.stop();
  std::lock_guard<std::mutex> l(o.mu);
  std::printf("sent %zu distinct submaps, duplicates acked %d, rejected %d, status %s\n",
              o.sent.size(), o.duplicates, o.rejected, o.status.c_str());
  ASSERT_EQ(o.done, 3) << "not every player finished";
  EXPECT_EQ(o.rejected, 0);
  if (kill_after > 0) {
    EXPECT_GT(killed_pid, 0) << "the server was never killed";
    EXPECT_NE(nodePid("/hermes_server"), killed_pid) << "the server was not started again";
    std::string dir;
    if (ros::param::get("/hermes_server/checkpoint_dir", dir) && !dir.empty()) {
      std::error_code ec;
      std::filesystem::remove_all(dir, ec);
    }
  }
  if (restart_broker_after > 0) {
    ASSERT_TRUE(broker_restarted) << "the broker was never killed and restarted";
    EXPECT_LT(accepted_at_broker_kill, o.sent.size()) << "the broker was killed after the run";
    for (const auto& [robot, j] : o.uplink) {
      EXPECT_TRUE(j.contains("pending") && j["pending"].empty()) << robot << " has unacknowledged submaps";
      EXPECT_EQ(j.value("transport", ""), "mqtt") << robot;
      std::printf("%s uplink: %s\n", robot.c_str(), j.value("mqtt", nlohmann::json()).dump().c_str());
    }
  }
  std::set<std::string> agents;
  for (const auto& [k, n] : o.sent) {
    agents.insert(std::get<0>(k));
    const int accepted = o.accepted.count(k) ? o.accepted.at(k) : 0;
    if (restart_broker_after > 0) {  // acks of the gap may be unseen; the spools drained (above)
      EXPECT_LE(accepted, 1) << "submap " << std::get<0>(k) << " seq " << std::get<2>(k) << " accepted twice";
    } else if (killed_pid) {
      EXPECT_LE(accepted, 1) << "submap " << std::get<0>(k) << " seq " << std::get<2>(k) << " accepted twice";
      EXPECT_TRUE(accepted == 1 || o.duplicate.count(k))
          << "submap " << std::get<0>(k) << " seq " << std::get<2>(k) << " never acknowledged";
    } else {
      EXPECT_EQ(accepted, 1) << "submap " << std::get<0>(k) << " seq " << std::get<2>(k)
                             << " not accepted exactly once";
    }
  }
  for (const auto& [k, n] : o.accepted) EXPECT_TRUE(o.sent.count(k)) << "accepted a submap never sent";
  EXPECT_EQ(agents.size(), 3u);
  hermes_tests::expectMergedAndApplied(o.status, 3, o.sent.size());

  // Each agent's published odometry (body poses) against its ground truth.
  for (const auto& [robot, seq] : kSequence) {
    auto ds = hermes::Dataset::open(data + "/" + seq, hermes::DatasetParams{});
    ASSERT_TRUE(ds.ok()) << ds.error();
    const hermes::Trajectory& est = o.odom[robot];
    EXPECT_GE(est.size(), (*ds)->info().frame_count * 8 / 10) << robot << ": odometry for too few frames";
    auto ev = hermes::eval::evaluateTrajectory((*ds)->info().groundtruth, est, hermes::eval::EvalParams{}, robot);
    ASSERT_TRUE(ev.ok()) << ev.error();
    std::printf("%s odometry: %zu poses, ATE %.4f m\n", robot.c_str(), est.size(), ev->ate.trans_m.rmse);
    EXPECT_LT(ev->ate.trans_m.rmse, 0.05) << robot;
  }

  // Merged keyframe paths (camera poses, world frame) vs rendered ground truth,
  // one common SE(3) alignment for all agents.
  std::vector<hermes::eval::AgentTrajectories> trajs;
  for (const auto& [robot, path] : o.paths) {
    ASSERT_TRUE(o.uuid_of_robot.count(robot));
    const std::string name = o.name_of_uuid[o.uuid_of_robot[robot]];
    ASSERT_TRUE(kSequence.count(name)) << "unknown agent name '" << name << "'";
    auto ds = hermes::Dataset::open(data + "/" + kSequence.at(name), hermes::DatasetParams{});
    ASSERT_TRUE(ds.ok()) << ds.error();
    const hermes::DatasetInfo& info = (*ds)->info();
    trajs.push_back({name, hermes::transformTrajectory(info.groundtruth, info.T_B_C), toTrajectory(path)});
  }
  hermes::eval::EvalParams ep;
  auto ev = hermes::eval::evaluateAgents(trajs, ep);
  ASSERT_TRUE(ev.ok()) << ev.error();
  std::printf("merged ATE %.4f m over %zu keyframes\n", ev->merged_ate.trans_m.rmse, ev->matched);
  EXPECT_LT(ev->merged_ate.trans_m.rmse, 0.10);

  // The server told each robot where its odometry frame sits in the world: its
  // last odometry pose through that transform lands on its ground truth (under
  // the merged map's alignment).
  if (mqtt) return;
  ASSERT_EQ(o.global.size(), 3u) << "not every robot got /hermes/global_pose";
  // Every placed robot got the map around it back, and acknowledged each packet
  // (one per server start a shutdown or a kill cut short aside).
  for (const auto& [uuid, g] : o.global) {
    const std::string name = o.name_of_uuid[uuid];
    const auto& sent = o.down_sent[uuid];
    const auto& acked = o.down_acked[uuid];
    std::printf("%s: %zu downlink packets, %zu B, %zu acknowledged\n", name.c_str(), sent.size(),
                o.down_bytes[uuid], acked.size());
    EXPECT_GE(sent.size(), 1u) << name << " got no /hermes/map_down";
    EXPECT_GE(acked.size() + 2, sent.size()) << name << " did not acknowledge its packets";
    for (const auto& k : acked) EXPECT_TRUE(sent.count(k)) << name << " acknowledged a packet never sent";
  }
  for (const auto& [uuid, g] : o.global) {
    const std::string name = o.name_of_uuid[uuid];
    ASSERT_TRUE(kSequence.count(name) && !o.odom[name].empty()) << "global pose for '" << name << "'";
    auto ds = hermes::Dataset::open(data + "/" + kSequence.at(name), hermes::DatasetParams{});
    ASSERT_TRUE(ds.ok()) << ds.error();
    const auto& tr = g.world_from_odom;
    const hermes::SE3 T_W_O(hermes::Quat(tr.rotation.w, tr.rotation.x, tr.rotation.y, tr.rotation.z),
                            hermes::Vec3(tr.translation.x, tr.translation.y, tr.translation.z));
    const hermes::StampedPose last = o.odom[name].back();
    hermes::SE3 T_gt;
    ASSERT_TRUE(hermes::interpolatePose((*ds)->info().groundtruth, last.t, &T_gt)) << name;
    const hermes::SE3 T_est = ev->merged_alignment.applyToPose(T_W_O * last.T_W_B);
    const double err = (T_est.translation() - T_gt.translation()).norm();
    std::printf("%s global pose at its last frame: %.4f m off (%llu merged keyframes)\n", name.c_str(), err,
                static_cast<unsigned long long>(g.keyframes));
    EXPECT_LT(err, 0.10) << name;
  }
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_multi_agent");
  return RUN_ALL_TESTS();
}

// The deployment authenticates (multi_agent.test turns it on as the launch
// files do): frames without a tag, with a wrong key's tag or from a robot
// without a key are refused with their reason code, while the agents above
// were accepted.
TEST(MultiAgent, UnauthenticatedFramesAreRefusedWithReasons) {
  ros::NodeHandle nh, pnh("~");
  std::string transport = "ros";
  pnh.param("transport", transport, transport);
  if (transport == "mqtt") {
    hermes::FrameKey stranger;
    stranger.bytes.fill(0x42);
    ASSERT_TRUE(g_broker) << "the first test starts the broker";
    auto watcher = observer("hermes-rostest-forger");
    ASSERT_TRUE(watcher);
    ros::WallDuration(0.5).sleep();  // SUBACK
    auto send = [&](const std::string& topic_robot, const std::string& robot, std::uint64_t seq,
                    const hermes::FrameKey* key) {
      ASSERT_TRUE(watcher->publish(hermes::transport::mqttTopic(topic_robot, hermes::transport::MqttChannel::kSubmap),
                                   forgedFrame(robot, seq, key), 2));
    };
    send("agent0", "agent0", 900001, nullptr);     // no tag
    send("agent0", "agent0", 900002, &stranger);   // not agent0's key
    send("intruder", "intruder", 900003, &stranger);  // no key for this robot
    send("intruder", "agent1", 900004, &stranger);    // agent1's identity on another robot's topic
    std::map<std::uint64_t, hermes::transport::AckMessage> acks;
    const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(10.0);
    while (acks.size() < 4 && ros::WallTime::now() < deadline) {
      ros::WallDuration(0.1).sleep();
      for (auto& e : watcher->drain()) {
        auto t = hermes::transport::parseMqttTopic(e.topic);
        if (e.kind != hermes::transport::MqttEvent::Kind::kMessage || !t ||
            t->channel != hermes::transport::MqttChannel::kAck)
          continue;
        auto a = hermes::transport::decodeAck(e.payload.data(), e.payload.size());
        if (a && a->seq >= 900000) acks[a->seq] = *a;
      }
    }
    ASSERT_EQ(acks.size(), 4u) << "not every forged frame was answered";
    const std::map<std::uint64_t, std::uint8_t> expected = {
        {900001, hermes_msgs::SubmapAck::REASON_MISSING_TAG},
        {900002, hermes_msgs::SubmapAck::REASON_BAD_TAG},
        {900003, hermes_msgs::SubmapAck::REASON_UNKNOWN_ROBOT},
        {900004, hermes_msgs::SubmapAck::REASON_ROUTING_MISMATCH}};
    for (const auto& [seq, code] : expected) {
      EXPECT_EQ(acks[seq].status, hermes::transport::AckStatus::kRejected) << seq;
      EXPECT_EQ(acks[seq].reason_code, code) << seq << ": " << acks[seq].reason;
      EXPECT_FALSE(acks[seq].reason.empty());
    }
    return;
  }
  std::mutex mu;
  std::map<std::uint64_t, hermes_msgs::SubmapAck> acks;
  auto sub = nh.subscribe<hermes_msgs::SubmapAck>(
      "/hermes/submap_ack", 100, [&](const hermes_msgs::SubmapAckConstPtr& a) {
        std::lock_guard<std::mutex> l(mu);
        if (a->seq >= 900000) acks[a->seq] = *a;
      });
  auto pub = nh.advertise<hermes_msgs::EncodedSubmap>("/hermes/submap", 10);
  ros::AsyncSpinner spinner(1);
  spinner.start();
  const ros::WallTime connect_deadline = ros::WallTime::now() + ros::WallDuration(10.0);
  while ((pub.getNumSubscribers() == 0 || sub.getNumPublishers() == 0) &&
         ros::WallTime::now() < connect_deadline)
    ros::WallDuration(0.1).sleep();
  ASSERT_GT(pub.getNumSubscribers(), 0u) << "the server does not listen on /hermes/submap";
  ros::WallDuration(0.5).sleep();

  hermes::FrameKey stranger_key;
  stranger_key.bytes.fill(0x42);
  auto frame = [&](const std::string& robot, std::uint64_t seq, const hermes::FrameKey* key) {
    hermes_msgs::EncodedSubmap m;
    m.header.stamp = ros::Time::now();
    m.data = forgedFrame(robot, seq, key);
    const auto h = hermes::peekFrame(m.data.data(), m.data.size());
    EXPECT_TRUE(h.ok());
    m.agent_uuid = hermes::toString(hermes::agentUuid(robot));
    m.session = h.ok() ? h->routing.session : 0;
    m.seq = seq;
    return m;
  };
  pub.publish(frame("agent0", 900001, nullptr));        // no tag
  pub.publish(frame("agent0", 900002, &stranger_key));  // not agent0's key
  pub.publish(frame("intruder", 900003, &stranger_key));  // no key for this robot
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(10.0);
  while (ros::WallTime::now() < deadline) {
    ros::WallDuration(0.1).sleep();
    std::lock_guard<std::mutex> l(mu);
    if (acks.size() == 3) break;
  }
  std::lock_guard<std::mutex> l(mu);
  ASSERT_EQ(acks.size(), 3u) << "not every forged frame was answered";
  const std::map<std::uint64_t, std::uint8_t> expected = {
      {900001, hermes_msgs::SubmapAck::REASON_MISSING_TAG},
      {900002, hermes_msgs::SubmapAck::REASON_BAD_TAG},
      {900003, hermes_msgs::SubmapAck::REASON_UNKNOWN_ROBOT}};
  for (const auto& [seq, code] : expected) {
    EXPECT_EQ(acks[seq].status, hermes_msgs::SubmapAck::REJECTED) << seq;
    EXPECT_EQ(acks[seq].reason_code, code) << seq << ": " << acks[seq].reason;
    EXPECT_FALSE(acks[seq].reason.empty());
  }
}
