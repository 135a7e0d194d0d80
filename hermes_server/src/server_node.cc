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
//        /hermes/global_map (sensor_msgs/PointCloud2 xyz + rgb, each point in its robot's colour, frame "world", latched)
//        /hermes/loops (visualization_msgs/Marker LINE_LIST of accepted loops)
//        /hermes/map_down (MapDown: server.downlink, the map around each placed
//        robot, planned on the merge thread; in: /hermes/map_down_ack)
//        TF world -> hermes_origin (1 Hz), so the fixed frame exists; the robots'
//        own nodelets publish world -> <robot>/odom from /hermes/global_pose
// Threading (~parallel, default true): the ROS-free ServerWorker
// (hermes/server/server_worker.h) merges on a thread of its own, one submap at
// a time; the one spinner thread runs the callbacks: a submap callback (or the
// MQTT poll) gets the verdict from the worker and sends the ack at once -
// decode, auth, admission and the journal write, never a merge. After every
// merge the merge thread publishes /hermes/global_pose (roscpp publishers are
// thread-safe) from the view the worker made of the map; the 1 Hz timer
// publishes status, paths, map and loops from the newest view, so no callback
// reads the map while it is merged. The status JSON's timings_ms.ack_latency
// is receive (roscpp's receipt time; for MQTT the poll) -> ack published [ms].
// ~parallel false: no merge thread, a ~process_period timer merges one submap
// per tick on the spinner thread (the old behaviour: an ack can wait a merge).
// At shutdown the merge thread finishes the merge it runs and stops; the node
// merges what is queued, optimises and writes the results.
// Params: ~config (YAML, default config/hermes.yaml of the source tree), ~parallel,
// ~output_dir (written at shutdown: TUM trajectories, PLY, metrics.json),
// ~process_period [s] (0.05), ~auth (bool: overrides server.auth.enabled;
// server.launch sets true), ~key_dir (overrides server.auth.key_dir). With
// authentication on, a missing or empty key directory stops the node.
// ~checkpoint_dir (overrides server.checkpoint_dir: with a directory the server
// journals every submap before acknowledging it, checkpoints after merges and
// on shutdown, and resumes from it on start; the core does all of it, see
// hermes/server/server.h).
// ~prior_map (overrides server.prior_map: start on an earlier mission's map, a
// folder holding its checkpoint, e.g. hermes run's OUT/map or a checkpoint_dir
// of that mission; never changed), ~prior_map_optional (bool: an unreadable
// prior map is a warning and an empty start instead of a fatal error).
// ~transport (ros | mqtt; default: the config's `transport`), ~mqtt_host,
// ~mqtt_port (override mqtt.host / mqtt.port): with mqtt the submaps and
// heartbeats come from hermes/+/submap and hermes/+/heartbeat through the broker
// and every ack goes to hermes/<robot>/ack, every global pose (as on
// /hermes/global_pose) also to hermes/<robot>/global_pose once a heartbeat named
// the robot (hermes_transport/mqtt_links.h), polled by a 20 ms wall timer on the
// spinner thread; /hermes/submap,
// /hermes/heartbeat and /hermes/submap_ack are then not used. An unreachable
// broker is reported and tried again with backoff.
#include <hermes_msgs/AgentHeartbeat.h>
#include <hermes_msgs/EncodedSubmap.h>
#include <hermes_msgs/GlobalPose.h>
#include <hermes_msgs/MapDown.h>
#include <hermes_msgs/MapDownAck.h>
#include <hermes_msgs/SubmapAck.h>
#include <nav_msgs/Path.h>
#include <ros/ros.h>
#include <sensor_msgs/PointCloud2.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <std_msgs/String.h>
#include <tf2_ros/transform_broadcaster.h>
#include <visualization_msgs/Marker.h>

#include <array>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>

#include "hermes/core/config_file.h"
#include "hermes/server/server.h"
#include "hermes/server/server_outputs.h"
#include "hermes/server/server_worker.h"
#include "hermes/transport/mqtt_links.h"

namespace {

using hermes::server::MergedView;
using hermes::server::Server;
using hermes::server::ServerWorker;

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

/// The global map as xyz + rgb points, each in its robot's colour (robotColour,
/// as the paths in config/rviz/hermes.rviz); grey when the robot is not known.
sensor_msgs::PointCloud2 toCloud(const std::vector<hermes::Vec3>& points,
                                 const std::vector<hermes::RobotId>& robots, const std_msgs::Header& h) {
  sensor_msgs::PointCloud2 cloud;
  cloud.header = h;
  sensor_msgs::PointCloud2Modifier mod(cloud);
  mod.setPointCloud2FieldsByString(2, "xyz", "rgb");
  mod.resize(points.size());
  sensor_msgs::PointCloud2Iterator<float> x(cloud, "x"), y(cloud, "y"), z(cloud, "z");
  sensor_msgs::PointCloud2Iterator<std::uint8_t> r(cloud, "r"), g(cloud, "g"), b(cloud, "b");
  for (std::size_t i = 0; i < points.size(); ++i) {
    const hermes::Vec3& p = points[i];
    *x = float(p.x());
    *y = float(p.y());
    *z = float(p.z());
    const std::array<std::uint8_t, 3> c =
        i < robots.size() ? hermes::server::robotColour(robots[i]) : std::array<std::uint8_t, 3>{160, 160, 160};
    *r = c[0];
    *g = c[1];
    *b = c[2];
    ++x, ++y, ++z, ++r, ++g, ++b;
  }
  return cloud;
}

class ServerNode {
 public:
  ServerNode(std::unique_ptr<Server> server, bool parallel, std::string output_dir, double period,
             std::unique_ptr<hermes::transport::MqttServerLink> mqtt)
      : output_dir_(std::move(output_dir)), mqtt_(std::move(mqtt)) {
    ros::NodeHandle nh;
    status_pub_ = nh.advertise<std_msgs::String>("/hermes/status", 10, true);
    map_pub_ = nh.advertise<sensor_msgs::PointCloud2>("/hermes/global_map", 1, true);
    loops_pub_ = nh.advertise<visualization_msgs::Marker>("/hermes/loops", 1, true);
    global_pub_ = nh.advertise<hermes_msgs::GlobalPose>("/hermes/global_pose", 100);
    hermes::server::ServerWorkerParams wp;
    wp.parallel = parallel;
    if (server->params().downlink.enabled && !mqtt_) {
      // A new epoch every start: the robots key what they took by (epoch, seq).
      downlink_ = std::make_unique<hermes::server::Downlink>(server->params().downlink,
                                                             ros::WallTime::now().toNSec() / 1000);
      down_pub_ = nh.advertise<hermes_msgs::MapDown>("/hermes/map_down", 20);
      down_ack_sub_ = nh.subscribe("/hermes/map_down_ack", 100, &ServerNode::onMapDownAck, this);
    }
    worker_ = std::make_unique<ServerWorker>(
        std::move(server), wp, [] { return ros::WallTime::now().toSec(); },
        [this](const MergedView& v) {
          if (ros::ok()) publishGlobalPoses(v, false);  // not once ROS shuts down (finish() stops the thread)
        },
        [this](const Server& s, double now) {
          if (ros::ok() && downlink_) sendDownlink(s, now);
        });
    if (mqtt_) {
      mqtt_timer_ = nh.createWallTimer(ros::WallDuration(0.02), [this](const ros::WallTimerEvent&) { onMqtt(); });
    } else {
      ack_pub_ = nh.advertise<hermes_msgs::SubmapAck>("/hermes/submap_ack", 100);
      submap_sub_ = nh.subscribe("/hermes/submap", 100, &ServerNode::onSubmap, this);
      hb_sub_ = nh.subscribe("/hermes/heartbeat", 10, &ServerNode::onHeartbeat, this);
    }
    if (!parallel)
      process_timer_ = nh.createWallTimer(ros::WallDuration(period), [this](const ros::WallTimerEvent&) {
        worker_->process(ros::WallTime::now().toSec(), 1);
      });
    publish_timer_ = nh.createWallTimer(ros::WallDuration(1.0),
                                        [this](const ros::WallTimerEvent&) { publishOutputs(); });
  }

  /// Stops the merge thread, merges what is left, optimises once more and
  /// writes the results folder.
  void finish() {
    worker_->stop();
    Server& server = worker_->server();
    server.process(ros::WallTime::now().toSec());  // ROS is shut down: nothing published
    if (auto s = server.mapManager().optimize(/*full=*/true); !s)
      ROS_WARN("hermes_server: final optimisation: %s", s.error().c_str());
    if (auto s = server.checkpoint(ros::WallTime::now().toSec()); !s)
      ROS_ERROR("hermes_server: last checkpoint: %s", s.error().c_str());
    if (output_dir_.empty()) return;
    std::error_code ec;
    std::filesystem::create_directories(output_dir_, ec);
    auto paths = hermes::server::writeAgentTrajectories(server.map(), output_dir_);
    if (!paths.ok()) ROS_ERROR("hermes_server: %s", paths.error().c_str());
    if (auto s = hermes::server::writePly(output_dir_ + "/global_map.ply",
                                          server.map().landmarkPositionsWorld(), true);
        !s)
      ROS_ERROR("hermes_server: %s", s.error().c_str());
    if (auto s = server.map().save(output_dir_ + "/global_map.hgm"); !s)
      ROS_ERROR("hermes_server: %s", s.error().c_str());
    if (auto s = hermes::writeMetricsJson(output_dir_ + "/metrics.json", worker_->metrics()); !s)
      ROS_ERROR("hermes_server: %s", s.error().c_str());
    ROS_INFO("hermes_server: results written to %s", output_dir_.c_str());
  }

 private:
  void onSubmap(const ros::MessageEvent<const hermes_msgs::EncodedSubmap>& event) {
    const hermes_msgs::EncodedSubmap& m = *event.getConstMessage();
    hermes::SubmapHeader claimed;
    const bool have_uuid = hermes::parseUuid(m.agent_uuid, &claimed.agent);
    claimed.session = m.session;
    claimed.seq = m.seq;
    const auto r = worker_->onFrame(m.data.data(), m.data.size(), have_uuid ? &claimed : nullptr,
                                    ros::WallTime::now().toSec());
    if (r.verdict == hermes::ArrivalVerdict::kRejected)
      ROS_WARN_THROTTLE(1.0, "hermes_server: rejected submap from '%s' seq %lu: %s",
                        m.agent_uuid.c_str(), static_cast<unsigned long>(m.seq), r.reason.c_str());
    ack_pub_.publish(makeAck(m, r));  // rejections are answered too, with the reason
    worker_->recordAckLatency((ros::Time::now() - event.getReceiptTime()).toSec() * 1e3);
  }

  /// MQTT: every frame received since the last tick, answered on its robot's ack topic.
  void onMqtt() {
    const ros::WallTime polled = ros::WallTime::now();
    hermes::transport::ServerLinkEvents ev = mqtt_->poll();
    for (const std::string& p : ev.problems) ROS_WARN_THROTTLE(1.0, "hermes_server: mqtt: %s", p.c_str());
    for (const hermes::transport::HeartbeatMessage& hb : ev.heartbeats)
      if (names_.emplace(hermes::toString(hb.agent), hb.name).second)
        ROS_INFO("hermes_server: agent %s is '%s' (MQTT)", hermes::toString(hb.agent).c_str(), hb.name.c_str());
    for (const hermes::transport::IncomingFrame& f : ev.frames) {
      const double now = ros::WallTime::now().toSec();
      const hermes::ReceiveResult r =
          mqtt_->handle(f, [&](const std::uint8_t* d, std::size_t n, const hermes::SubmapHeader* claimed) {
            return worker_->onFrame(d, n, claimed, now);
          });
      worker_->recordAckLatency((ros::WallTime::now() - polled).toSec() * 1e3);
      if (r.verdict == hermes::ArrivalVerdict::kRejected)
        ROS_WARN_THROTTLE(1.0, "hermes_server: rejected submap on hermes/%s/submap seq %lu: %s", f.agent.c_str(),
                          static_cast<unsigned long>(r.routing.seq), r.reason.c_str());
    }
  }

  /// On the merge thread (after merges, and every second while idle): the
  /// downlink's packets for the robots' current sessions (downlink.h).
  void sendDownlink(const Server& s, double now) {
    std::vector<hermes::server::DownlinkRecipient> recipients;
    {
      const auto lock = s.lockIntake();
      const hermes::Bookkeeper& bk = s.bookkeeper();
      for (hermes::RobotId r : bk.robots()) {
        const hermes::AgentStats* st = bk.stats(r);
        if (st && !bk.isPrior(r)) recipients.push_back({r, st->uuid, st->current_session});
      }
    }
    std::lock_guard<std::mutex> lock(down_mu_);
    for (const hermes::server::Downlink::Outgoing& o : downlink_->plan(s.map(), recipients, now)) {
      hermes_msgs::MapDown m;
      m.header.stamp = ros::Time::now();
      m.agent_uuid = hermes::toString(o.agent);
      m.epoch = downlink_->epoch();
      m.seq = o.seq;
      m.data = *o.bytes;
      down_pub_.publish(m);
    }
  }

  void onMapDownAck(const hermes_msgs::MapDownAckConstPtr& a) {
    hermes::MapDownAck ack;
    if (!hermes::parseUuid(a->agent_uuid, &ack.agent)) return;
    ack.epoch = a->epoch;
    ack.seq = a->seq;
    std::lock_guard<std::mutex> lock(down_mu_);
    downlink_->onAck(ack, ros::WallTime::now().toSec());
  }

  void onHeartbeat(const hermes_msgs::AgentHeartbeatConstPtr& h) {
    if (!h->name.empty() && names_.emplace(h->agent_uuid, h->name).second)
      ROS_INFO("hermes_server: agent %s is '%s'", h->agent_uuid.c_str(), h->name.c_str());
  }

  /// After a merge (on the merge thread) and once a second: every anchored
  /// robot's current session hears its world <- odom. Over MQTT too with `mqtt`
  /// (only from the spinner thread, which owns the MQTT link and the names).
  void publishGlobalPoses(const MergedView& view, bool mqtt) {
    const ros::Time now = ros::Time::now();
    for (const MergedView::RobotPose& rp : view.poses) {
      const hermes::GlobalPoseUpdate& u = rp.update;
      hermes_msgs::GlobalPose m;
      m.header.stamp = now;
      m.header.frame_id = "world";
      m.agent_uuid = hermes::toString(rp.uuid);
      m.robot_id = rp.robot;
      m.session = u.session;
      m.keyframe_stamp = u.keyframe_stamp;
      m.keyframes = u.keyframes;
      const geometry_msgs::Pose p = toPose(u.T_W_O);
      m.world_from_odom.translation.x = p.position.x;
      m.world_from_odom.translation.y = p.position.y;
      m.world_from_odom.translation.z = p.position.z;
      m.world_from_odom.rotation = p.orientation;
      global_pub_.publish(m);
      if (mqtt && mqtt_) sendGlobalPoseMqtt(m.agent_uuid, hermes::transport::GlobalPoseMessage{rp.uuid, u});
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
    const std::shared_ptr<const MergedView> view = worker_->view();
    publishGlobalPoses(*view, true);  // also once a second: a robot that (re)connects hears it
    std_msgs::String status;
    status.data = hermes::metricsToJsonString(worker_->metrics(), -1);
    status_pub_.publish(status);
    std_msgs::Header h;
    h.frame_id = "world";
    h.stamp = ros::Time::now();
    publishFrames(h);
    if (view->version == published_version_) return;  // the map did not change
    published_version_ = view->version;
    for (const auto& [r, traj] : view->paths) {
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
    map_pub_.publish(toCloud(view->landmarks, view->landmark_robots, h));
    // Loops: hairlines, translucent, so hundreds of them do not bury the map.
    visualization_msgs::Marker loops;
    loops.header = h;
    loops.ns = "loops";
    loops.type = visualization_msgs::Marker::LINE_LIST;
    loops.scale.x = 0.004;
    loops.color.r = 1.0;
    loops.color.g = 0.85;
    loops.color.b = 0.3;
    loops.color.a = 0.35;
    loops.pose.orientation.w = 1.0;
    for (const auto& [a, b] : view->loops) {
      loops.points.push_back(toPoint(a));
      loops.points.push_back(toPoint(b));
    }
    loops_pub_.publish(loops);
  }

  std::string output_dir_;
  std::unique_ptr<hermes::transport::MqttServerLink> mqtt_;  ///< set: transport mqtt
  ros::WallTimer mqtt_timer_;
  ros::Publisher ack_pub_, status_pub_, map_pub_, loops_pub_, global_pub_;
  std::map<hermes::RobotId, ros::Publisher> path_pubs_;
  std::map<std::string, std::string> names_;
  ros::Subscriber submap_sub_, hb_sub_;
  ros::WallTimer process_timer_, publish_timer_;
  tf2_ros::TransformBroadcaster tf_;
  std::uint64_t published_version_ = 0;  ///< view last published (0: none; a resumed server holds a map)
  std::mutex down_mu_;  ///< downlink_: planned on the merge thread, acknowledged on the spinner
  std::unique_ptr<hermes::server::Downlink> downlink_;  ///< server.downlink (ROS transport)
  ros::Publisher down_pub_;
  ros::Subscriber down_ack_sub_;
  std::unique_ptr<ServerWorker> worker_;  ///< last: its merge thread ends first (publishes with the above)
};

}  // namespace

int main(int argc, char** argv) {
  ros::init(argc, argv, "hermes_server");
  ros::NodeHandle pnh("~");
  std::string config_file = std::string(HERMES_SOURCE_DIR) + "/config/hermes.yaml", output_dir;
  std::string checkpoint_dir;
  double period = 0.05;
  bool parallel = true;
  pnh.param("config", config_file, config_file);
  pnh.param("parallel", parallel, parallel);
  pnh.param("output_dir", output_dir, output_dir);
  pnh.param("process_period", period, period);
  // ~auth / ~key_dir (launch arguments; on by default there) override the config.
  std::vector<std::string> sets;
  if (bool auth = false; pnh.getParam("auth", auth))
    sets.push_back(std::string("server.auth.enabled=") + (auth ? "true" : "false"));
  if (std::string key_dir; pnh.getParam("key_dir", key_dir) && !key_dir.empty())
    sets.push_back("server.auth.key_dir=" + key_dir);
  pnh.param("checkpoint_dir", checkpoint_dir, checkpoint_dir);
  if (std::string prior; pnh.getParam("prior_map", prior) && !prior.empty()) sets.push_back("server.prior_map=" + prior);
  if (bool optional = false; pnh.getParam("prior_map_optional", optional))
    sets.push_back(std::string("server.prior_map_optional=") + (optional ? "true" : "false"));
  auto config = hermes::loadConfig(config_file, sets);
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
  if (!resume.prior_map.empty())
    ROS_INFO("hermes_server: on the prior map %s: %d robots, %zu keyframes, in its world frame",
             resume.prior_map.c_str(), (*server)->mapManager().priorAgents(), (*server)->map().keyframeCount());
  ServerNode node(std::move(*server), parallel, output_dir, period, std::move(mqtt));
  const std::string auth = params.auth.enabled ? "on, keys in " + params.auth.key_dir : "OFF";
  ROS_INFO("hermes_server: ready (config %s; merging %s; authentication %s%s%s)", config_file.c_str(),
           parallel ? "on its own thread" : "on the spinner thread", auth.c_str(), params.checkpoint.enabled() ? "; checkpoints in " : "",
           params.checkpoint.dir.c_str());
  ros::spin();
  node.finish();
  return 0;
}
