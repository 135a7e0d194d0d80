// hermes_server_node: the edge server on ROS. Thin over the ROS-free
// hermes::server::Server (decode, dedup, credibility queue, loops, PCM, pose
// graph). Topics (global):
//   in : /hermes/submap (EncodedSubmap), /hermes/heartbeat (AgentHeartbeat)
//   out: /hermes/submap_ack (SubmapAck, for every frame, rejections with reason)
//        /hermes/global_pose (GlobalPose: after every merge, each anchored robot's
//        world <- odom at its newest merged keyframe; the robot's nodelet turns
//        it into TF world -> <robot>/odom and odom_global)
//        /hermes/status (std_msgs/String, metrics JSON, 1 Hz)
//        /hermes/path/<robot id> (nav_msgs/Path of merged keyframes, frame "world")
//        /hermes/global_map (sensor_msgs/PointCloud2, frame "world", latched)
//        /hermes/loops (visualization_msgs/Marker LINE_LIST of accepted loops)
//        TF world -> hermes_origin (1 Hz), so the fixed frame exists; the robots'
//        own nodelets publish world -> <robot>/odom from /hermes/global_pose
// Threading: one spinner thread; acks are sent in the submap callback, merging
// runs from a timer one submap per tick, so an ack waits at most one merge.
// Params: ~config (YAML, default config/hermes.yaml of the source tree),
// ~output_dir (written at shutdown: TUM trajectories, PLY, metrics.json),
// ~process_period [s] (0.05), ~auth (bool: overrides server.auth.enabled;
// server.launch sets true), ~key_dir (overrides server.auth.key_dir). With
// authentication on, a missing or empty key directory stops the node.
// ~checkpoint_dir (overrides server.checkpoint_dir: with a directory the server
// journals every submap before acknowledging it, checkpoints after merges and
// on shutdown, and resumes from it on start; the core does all of it, see
// hermes/server/server.h).
// ~transport (ros | mqtt; default: the config's `transport`), ~mqtt_host,
// ~mqtt_port (override mqtt.host / mqtt.port): with mqtt the submaps and
// heartbeats come from hermes/+/submap and hermes/+/heartbeat through the broker
// and every ack goes to hermes/<robot>/ack, every global pose (as on
// /hermes/global_pose) also to hermes/<robot>/global_pose once a heartbeat named
// the robot (hermes_transport/mqtt_links.h),
// handled by a 20 ms wall timer on the spinner thread; /hermes/submap,
// /hermes/heartbeat and /hermes/submap_ack are then not used. An unreachable
// broker is reported and tried again with backoff.
#include <hermes_msgs/AgentHeartbeat.h>
#include <hermes_msgs/EncodedSubmap.h>
#include <hermes_msgs/GlobalPose.h>
#include <hermes_msgs/SubmapAck.h>
#include <nav_msgs/Path.h>
#include <ros/ros.h>
#include <sensor_msgs/PointCloud2.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <std_msgs/String.h>
#include <tf2_ros/transform_broadcaster.h>
#include <visualization_msgs/Marker.h>

#include <filesystem>
#include <map>
#include <memory>

#include "hermes/agent/run_config.h"
#include "hermes/server/server.h"
#include "hermes/server/server_outputs.h"
#include "hermes/transport/mqtt_links.h"

namespace {

using hermes::server::Server;

hermes_msgs::SubmapAck makeAck(const hermes_msgs::EncodedSubmap& m, const hermes::ReceiveResult& r) {
  hermes_msgs::SubmapAck ack;
  ack.header.stamp = ros::Time::now();
  ack.agent_uuid = m.agent_uuid;
  ack.session = m.session;
  ack.seq = m.seq;
  ack.robot_id = r.robot;
  switch (r.verdict) {
    case hermes::ArrivalVerdict::kAccept: ack.status = hermes_msgs::SubmapAck::ACCEPTED; break;
    case hermes::ArrivalVerdict::kDuplicate:
    case hermes::ArrivalVerdict::kStale: ack.status = hermes_msgs::SubmapAck::DUPLICATE; break;
    case hermes::ArrivalVerdict::kRejected: ack.status = hermes_msgs::SubmapAck::REJECTED; break;
  }
  static_assert(hermes_msgs::SubmapAck::REASON_REFUSED + 1 == hermes::kReceiveCodes,
                "SubmapAck reason codes mirror hermes::ReceiveCode");
  ack.reason_code = static_cast<std::uint8_t>(r.code);
  ack.reason = r.reason;
  return ack;
}

geometry_msgs::Point toPoint(const hermes::Vec3& v) {
  geometry_msgs::Point p;
  p.x = v.x();
  p.y = v.y();
  p.z = v.z();
  return p;
}

geometry_msgs::Pose toPose(const hermes::SE3& T) {
  geometry_msgs::Pose p;
  p.position = toPoint(T.translation());
  const hermes::Quat q = T.quat();
  p.orientation.x = q.x();
  p.orientation.y = q.y();
  p.orientation.z = q.z();
  p.orientation.w = q.w();
  return p;
}

sensor_msgs::PointCloud2 toCloud(const std::vector<hermes::Vec3>& points, const std_msgs::Header& h) {
  sensor_msgs::PointCloud2 cloud;
  cloud.header = h;
  sensor_msgs::PointCloud2Modifier mod(cloud);
  mod.setPointCloud2FieldsByString(1, "xyz");
  mod.resize(points.size());
  sensor_msgs::PointCloud2Iterator<float> x(cloud, "x"), y(cloud, "y"), z(cloud, "z");
  for (const hermes::Vec3& p : points) {
    *x = float(p.x());
    *y = float(p.y());
    *z = float(p.z());
    ++x, ++y, ++z;
  }
  return cloud;
}

class ServerNode {
 public:
  ServerNode(std::unique_ptr<Server> server, std::string output_dir, double period,
             std::unique_ptr<hermes::transport::MqttServerLink> mqtt)
      : server_(std::move(server)), output_dir_(std::move(output_dir)), mqtt_(std::move(mqtt)) {
    ros::NodeHandle nh;
    status_pub_ = nh.advertise<std_msgs::String>("/hermes/status", 10, true);
    map_pub_ = nh.advertise<sensor_msgs::PointCloud2>("/hermes/global_map", 1, true);
    loops_pub_ = nh.advertise<visualization_msgs::Marker>("/hermes/loops", 1, true);
    if (mqtt_) {
      mqtt_timer_ = nh.createWallTimer(ros::WallDuration(0.02), [this](const ros::WallTimerEvent&) { onMqtt(); });
    } else {
      ack_pub_ = nh.advertise<hermes_msgs::SubmapAck>("/hermes/submap_ack", 100);
      submap_sub_ = nh.subscribe("/hermes/submap", 100, &ServerNode::onSubmap, this);
      hb_sub_ = nh.subscribe("/hermes/heartbeat", 10, &ServerNode::onHeartbeat, this);
    }
    global_pub_ = nh.advertise<hermes_msgs::GlobalPose>("/hermes/global_pose", 100);
    process_timer_ = nh.createWallTimer(ros::WallDuration(period), [this](const ros::WallTimerEvent&) {
      if (server_->process(ros::WallTime::now().toSec(), 1) > 0) {
        dirty_ = true;
        publishGlobalPoses();
      }
    });
    publish_timer_ = nh.createWallTimer(ros::WallDuration(1.0),
                                        [this](const ros::WallTimerEvent&) { publishOutputs(); });
  }

  /// Merges what is left, optimises once more and writes the results folder.
  void finish() {
    server_->process(ros::WallTime::now().toSec());
    if (auto s = server_->mapManager().optimize(/*full=*/true); !s)
      ROS_WARN("hermes_server: final optimisation: %s", s.error().c_str());
    if (auto s = server_->checkpoint(ros::WallTime::now().toSec()); !s)
      ROS_ERROR("hermes_server: last checkpoint: %s", s.error().c_str());
    if (output_dir_.empty()) return;
    std::error_code ec;
    std::filesystem::create_directories(output_dir_, ec);
    auto paths = hermes::server::writeAgentTrajectories(server_->map(), output_dir_);
    if (!paths.ok()) ROS_ERROR("hermes_server: %s", paths.error().c_str());
    if (auto s = hermes::server::writePly(output_dir_ + "/global_map.ply",
                                          server_->map().landmarkPositionsWorld(), true);
        !s)
      ROS_ERROR("hermes_server: %s", s.error().c_str());
    if (auto s = server_->map().save(output_dir_ + "/global_map.hgm"); !s)
      ROS_ERROR("hermes_server: %s", s.error().c_str());
    if (auto s = hermes::writeMetricsJson(output_dir_ + "/metrics.json",
                                          hermes::server::serverMetrics(*server_));
        !s)
      ROS_ERROR("hermes_server: %s", s.error().c_str());
    ROS_INFO("hermes_server: results written to %s", output_dir_.c_str());
  }

 private:
  void onSubmap(const hermes_msgs::EncodedSubmapConstPtr& m) {
    hermes::SubmapHeader claimed;
    const bool have_uuid = hermes::parseUuid(m->agent_uuid, &claimed.agent);
    claimed.session = m->session;
    claimed.seq = m->seq;
    const auto r = server_->onFrame(m->data.data(), m->data.size(), have_uuid ? &claimed : nullptr,
                                    ros::WallTime::now().toSec());
    if (r.verdict == hermes::ArrivalVerdict::kRejected)
      ROS_WARN_THROTTLE(1.0, "hermes_server: rejected submap from '%s' seq %lu: %s",
                        m->agent_uuid.c_str(), static_cast<unsigned long>(m->seq), r.reason.c_str());
    ack_pub_.publish(makeAck(*m, r));  // rejections are answered too, with the reason
  }

  /// MQTT: every frame received since the last tick, answered on its robot's ack topic.
  void onMqtt() {
    hermes::transport::ServerLinkEvents ev = mqtt_->poll();
    for (const std::string& p : ev.problems) ROS_WARN_THROTTLE(1.0, "hermes_server: mqtt: %s", p.c_str());
    for (const hermes::transport::HeartbeatMessage& hb : ev.heartbeats)
      if (names_.emplace(hermes::toString(hb.agent), hb.name).second)
        ROS_INFO("hermes_server: agent %s is '%s' (MQTT)", hermes::toString(hb.agent).c_str(), hb.name.c_str());
    for (const hermes::transport::IncomingFrame& f : ev.frames) {
      const double now = ros::WallTime::now().toSec();
      const hermes::ReceiveResult r =
          mqtt_->handle(f, [&](const std::uint8_t* d, std::size_t n, const hermes::SubmapHeader* claimed) {
            return server_->onFrame(d, n, claimed, now);
          });
      if (r.verdict == hermes::ArrivalVerdict::kRejected)
        ROS_WARN_THROTTLE(1.0, "hermes_server: rejected submap on hermes/%s/submap seq %lu: %s", f.agent.c_str(),
                          static_cast<unsigned long>(r.routing.seq), r.reason.c_str());
    }
  }

  void onHeartbeat(const hermes_msgs::AgentHeartbeatConstPtr& h) {
    if (!h->name.empty() && names_.emplace(h->agent_uuid, h->name).second)
      ROS_INFO("hermes_server: agent %s is '%s'", h->agent_uuid.c_str(), h->name.c_str());
  }

  /// After a merge: every anchored robot's current session hears its world <- odom.
  void publishGlobalPoses() {
    const ros::Time now = ros::Time::now();
    for (const auto& [robot, u] : hermes::server::globalPoseUpdates(server_->map())) {
      const hermes::AgentStats* st = server_->bookkeeper().stats(robot);
      if (!st || st->current_session != u.session) continue;
      hermes_msgs::GlobalPose m;
      m.header.stamp = now;
      m.header.frame_id = "world";
      m.agent_uuid = hermes::toString(st->uuid);
      m.robot_id = robot;
      m.session = u.session;
      m.keyframe_stamp = u.keyframe_stamp;
      m.keyframes = u.keyframes;
      const geometry_msgs::Pose p = toPose(u.T_W_O);
      m.world_from_odom.translation.x = p.position.x;
      m.world_from_odom.translation.y = p.position.y;
      m.world_from_odom.translation.z = p.position.z;
      m.world_from_odom.rotation = p.orientation;
      global_pub_.publish(m);
      if (mqtt_) sendGlobalPoseMqtt(m.agent_uuid, hermes::transport::GlobalPoseMessage{st->uuid, u});
    }
  }

  /// MQTT: to hermes/<robot>/global_pose once the robot's name is known (heartbeats).
  void sendGlobalPoseMqtt(const std::string& uuid, const hermes::transport::GlobalPoseMessage& msg) {
    auto name = names_.find(uuid);
    if (name == names_.end()) return;
    if (hermes::Status s = mqtt_->sendGlobalPose(name->second, msg); !s)
      ROS_WARN_THROTTLE(5.0, "hermes_server: global pose of '%s' over MQTT: %s", name->second.c_str(),
                        s.error().c_str());
  }

  /// The fixed frame exists before any robot publishes its world -> odom.
  void publishFrames(const std_msgs::Header& h) {
    geometry_msgs::TransformStamped tf;
    tf.header = h;
    tf.child_frame_id = "hermes_origin";
    tf.transform.rotation.w = 1.0;
    tf_.sendTransform(tf);
  }

  void publishOutputs() {
    publishGlobalPoses();  // also once a second: a robot that (re)connects hears it
    std_msgs::String status;
    status.data = hermes::metricsToJsonString(hermes::server::serverMetrics(*server_), -1);
    status_pub_.publish(status);
    if (!dirty_) {
      std_msgs::Header h;
      h.frame_id = "world";
      h.stamp = ros::Time::now();
      publishFrames(h);
      return;
    }
    dirty_ = false;
    const hermes::server::GlobalMap& map = server_->map();
    std_msgs::Header h;
    h.frame_id = "world";
    h.stamp = ros::Time::now();
    for (hermes::RobotId r : server_->bookkeeper().robots()) {
      const hermes::Trajectory traj = hermes::server::agentTrajectory(map, r);
      if (traj.empty()) continue;
      nav_msgs::Path path;
      path.header = h;
      for (const hermes::StampedPose& p : traj) {
        geometry_msgs::PoseStamped ps;
        ps.header.frame_id = "world";
        ps.header.stamp = ros::Time(p.t);
        ps.pose = toPose(p.T_W_B);
        path.poses.push_back(ps);
      }
      auto it = path_pubs_.find(r);
      if (it == path_pubs_.end())
        it = path_pubs_
                 .emplace(r, ros::NodeHandle().advertise<nav_msgs::Path>(
                                 "/hermes/path/" + std::to_string(r), 1, true))
                 .first;
      it->second.publish(path);
    }
    map_pub_.publish(toCloud(map.landmarkPositionsWorld(), h));
    publishFrames(h);
    visualization_msgs::Marker loops;
    loops.header = h;
    loops.ns = "loops";
    loops.type = visualization_msgs::Marker::LINE_LIST;
    loops.scale.x = 0.02;
    loops.color.r = 1.0;
    loops.color.a = 1.0;
    loops.pose.orientation.w = 1.0;
    for (const hermes::server::LoopEdge& l : map.loops) {
      const auto* a = map.keyframe(l.a);
      const auto* b = map.keyframe(l.b);
      const auto* ta = map.trajectory(l.a.agent, l.a.session);
      const auto* tb = map.trajectory(l.b.agent, l.b.session);
      if (!l.accepted || !a || !b || !ta || !tb || !ta->anchored || !tb->anchored) continue;
      loops.points.push_back(toPoint(a->T_W_C.translation()));
      loops.points.push_back(toPoint(b->T_W_C.translation()));
    }
    loops_pub_.publish(loops);
  }

  std::unique_ptr<Server> server_;
  std::string output_dir_;
  std::unique_ptr<hermes::transport::MqttServerLink> mqtt_;  ///< set: transport mqtt
  ros::WallTimer mqtt_timer_;
  ros::Publisher ack_pub_, status_pub_, map_pub_, loops_pub_, global_pub_;
  std::map<hermes::RobotId, ros::Publisher> path_pubs_;
  std::map<std::string, std::string> names_;
  ros::Subscriber submap_sub_, hb_sub_;
  ros::WallTimer process_timer_, publish_timer_;
  tf2_ros::TransformBroadcaster tf_;
  bool dirty_ = true;  ///< the map changed since it was last published (a resumed server holds one)
};

}  // namespace

int main(int argc, char** argv) {
  ros::init(argc, argv, "hermes_server");
  ros::NodeHandle pnh("~");
  std::string config_file = std::string(HERMES_SOURCE_DIR) + "/config/hermes.yaml", output_dir;
  std::string checkpoint_dir;
  double period = 0.05;
  pnh.param("config", config_file, config_file);
  pnh.param("output_dir", output_dir, output_dir);
  pnh.param("process_period", period, period);
  // ~auth / ~key_dir (launch arguments; on by default there) override the config.
  std::vector<std::string> sets;
  if (bool auth = false; pnh.getParam("auth", auth))
    sets.push_back(std::string("server.auth.enabled=") + (auth ? "true" : "false"));
  if (std::string key_dir; pnh.getParam("key_dir", key_dir) && !key_dir.empty())
    sets.push_back("server.auth.key_dir=" + key_dir);
  pnh.param("checkpoint_dir", checkpoint_dir, checkpoint_dir);
  auto config = hermes::agent::loadRunConfig(config_file, sets);
  if (!config.ok()) {
    ROS_FATAL("hermes_server: %s", config.error().c_str());
    return 2;
  }
  hermes::transport::TransportParams transport;
  if (auto s = transport.read(*config); !s) {
    ROS_FATAL("hermes_server: %s (in %s)", s.error().c_str(), config_file.c_str());
    return 2;
  }
  if (std::string kind; pnh.getParam("transport", kind) && !kind.empty()) transport.kind = kind;
  pnh.param("mqtt_host", transport.mqtt.host, transport.mqtt.host);
  pnh.param("mqtt_port", transport.mqtt.port, transport.mqtt.port);
  if (auto s = transport.validate(); !s) {
    ROS_FATAL("hermes_server: ~transport / ~mqtt_*: %s", s.error().c_str());
    return 2;
  }
  std::unique_ptr<hermes::transport::MqttServerLink> mqtt;
  if (transport.mqttEnabled()) {
    auto link = hermes::transport::MqttServerLink::create(transport.mqtt);
    if (!link.ok()) {
      ROS_FATAL("hermes_server: %s", link.error().c_str());
      return 2;
    }
    mqtt = std::move(*link);
    mqtt->client().start();
    if (auto s = mqtt->client().waitConnected(transport.mqtt.connect_timeout_s); !s)
      ROS_ERROR("hermes_server: %s", s.error().c_str());
    else
      ROS_INFO("hermes_server: submaps over MQTT, broker %s, client id %s", mqtt->client().broker().c_str(),
               mqtt->client().clientId().c_str());
  }
  hermes::server::ServerParams params;
  if (auto s = params.read(*config, "server."); !s) {
    ROS_FATAL("hermes_server: %s (in %s)", s.error().c_str(), config_file.c_str());
    return 2;
  }
  if (!checkpoint_dir.empty()) params.checkpoint.dir = checkpoint_dir;
  if (!(period > 0)) {
    ROS_FATAL("hermes_server: ~process_period must be > 0");
    return 2;
  }
  auto server = Server::create(params, HERMES_SOURCE_DIR);
  if (!server.ok()) {
    ROS_FATAL("hermes_server: %s", server.error().c_str());
    return 2;
  }
  const hermes::server::ResumeReport& resume = (*server)->resumeReport();
  for (const std::string& p : resume.problems) ROS_WARN("hermes_server: %s", p.c_str());
  if (resume.resumed)
    ROS_INFO("hermes_server: resumed from %s (+%zu journalled submaps) in %.0f ms: %zu agents, "
             "%zu submaps pending",
             resume.checkpoint.empty() ? "the journal" : resume.checkpoint.c_str(),
             resume.journal_replayed, resume.load_ms, (*server)->bookkeeper().robots().size(),
             (*server)->pending());
  ServerNode node(std::move(*server), output_dir, period, std::move(mqtt));
  const std::string auth = params.auth.enabled ? "on, keys in " + params.auth.key_dir : "OFF";
  ROS_INFO("hermes_server: ready (config %s; authentication %s%s%s)", config_file.c_str(),
           auth.c_str(), params.checkpoint.enabled() ? "; checkpoints in " : "",
           params.checkpoint.dir.c_str());
  ros::spin();
  node.finish();
  return 0;
}
