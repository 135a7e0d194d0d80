// Agent nodelet: one robot. Feeds synchronised rectified images into the
// ROS-free hermes::agent::AgentPipeline (tracking, local mapping, 5-s windows,
// distillation, disk spool) and connects its uplink to the server's topics.
//   in : stereo: left/image_rect + right/image_rect (ExactTime), left|right/camera_info
//        rgbd  : rgb/image_rect + depth/image_rect (ExactTime), rgb/camera_info
//        done (std_msgs/Empty): end of the sequence, send the last partial window
//        /hermes/submap_ack (acks for this agent's uuid)
//   out: odom (nav_msgs/Odometry, frame <robot>/odom, child <robot>/base_link),
//        TF <robot>/odom -> <robot>/base_link, /hermes/submap, /hermes/heartbeat (1 Hz)
//        uplink_status (std_msgs/String JSON, latched; after every new submap and at
//        1 Hz): session, submaps created by this process, spool pending keys/bytes,
//        spool cap -- what the delivery tests count as "sent"
// Params (private): robot (default: the namespace), mode (stereo|rgbd),
// config (YAML, default config/hermes.yaml), dataset (optional folder: camera and
// body<-camera extrinsic taken from it instead of camera_info), spool_dir
// (default /tmp/hermes_spool/<robot>), clear_spool (false: unacked submaps of
// a previous run are resent). The uplink runs on wall time. All
// callbacks take one mutex: the pipeline is not thread-safe.
#include <hermes_msgs/AgentHeartbeat.h>
#include <hermes_msgs/EncodedSubmap.h>
#include <hermes_msgs/SubmapAck.h>
#include <message_filters/subscriber.h>
#include <message_filters/time_synchronizer.h>
#include <nav_msgs/Odometry.h>
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>
#include <ros/ros.h>
#include <std_msgs/Empty.h>
#include <std_msgs/String.h>
#include <tf2_ros/transform_broadcaster.h>

#include <unistd.h>

#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>

#include <nlohmann/json.hpp>

#include "hermes/agent/agent_pipeline.h"
#include "hermes/agent/run_config.h"
#include "ros_convert.h"

namespace hermes_agent {

using ImageSub = message_filters::Subscriber<sensor_msgs::Image>;
using ImageSync = message_filters::TimeSynchronizer<sensor_msgs::Image, sensor_msgs::Image>;

class AgentNodelet : public nodelet::Nodelet {
 private:
  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    std::string ns = nh.getNamespace();
    while (!ns.empty() && ns.front() == '/') ns.erase(0, 1);
    pnh.param("robot", robot_, ns.empty() ? std::string("agent") : ns);
    pnh.param("mode", mode_, std::string("stereo"));
    std::string config_file = std::string(HERMES_SOURCE_DIR) + "/config/hermes.yaml", dataset;
    pnh.param("config", config_file, config_file);
    pnh.param("dataset", dataset, dataset);
    if (mode_ != "stereo" && mode_ != "rgbd") {
      NODELET_FATAL("Agent %s: ~mode must be stereo or rgbd, got '%s'", robot_.c_str(), mode_.c_str());
      return;
    }
    auto config = hermes::agent::loadRunConfig(config_file, {});
    hermes::agent::RunParams run;
    if (!config.ok() || !run.read(*config)) {
      NODELET_FATAL("Agent %s: config %s: %s", robot_.c_str(), config_file.c_str(),
                    config.ok() ? run.read(*config).error().c_str() : config.error().c_str());
      return;
    }
    params_ = run.agent;
    pnh.param("spool_dir", params_.uplink.buffer.dir, "/tmp/hermes_spool/" + robot_);
    bool clear_spool = false;  // tests and demos: start without the previous run's backlog
    pnh.param("clear_spool", clear_spool, clear_spool);
    if (clear_spool) {  // drop the backlog, keep the session counter (see discardPending)
      auto spool = hermes::agent::MapBuffer::open(params_.uplink.buffer);
      auto dropped = spool.ok() ? spool->discardPending()
                                : hermes::Expected<std::size_t>(hermes::Error{spool.error()});
      if (!dropped.ok()) {
        NODELET_FATAL("Agent %s: clear_spool: %s", robot_.c_str(), dropped.error().c_str());
        return;
      }
      if (*dropped > 0)
        NODELET_WARN("Agent %s: clear_spool: dropped %zu unacknowledged submaps of a previous run",
                     robot_.c_str(), *dropped);
    }
    if (!dataset.empty()) {  // camera from the dataset folder (rectified K, T_B_C)
      auto ds = hermes::Dataset::open(dataset, run.dataset);
      if (!ds.ok()) {
        NODELET_FATAL("Agent %s: dataset %s: %s", robot_.c_str(), dataset.c_str(), ds.error().c_str());
        return;
      }
      const hermes::DatasetInfo& info = (*ds)->info();
      camera_ = hermes::agent::AgentCamera{info.K, info.baseline, info.T_B_C};
    }
    odom_pub_ = nh.advertise<nav_msgs::Odometry>("odom", 50);
    submap_pub_ = nh.advertise<hermes_msgs::EncodedSubmap>("/hermes/submap", 20);
    heartbeat_pub_ = nh.advertise<hermes_msgs::AgentHeartbeat>("/hermes/heartbeat", 5);
    uplink_status_pub_ = nh.advertise<std_msgs::String>("uplink_status", 20, true);
    ack_sub_ = nh.subscribe("/hermes/submap_ack", 100, &AgentNodelet::onAck, this);
    done_sub_ = nh.subscribe("done", 1, &AgentNodelet::onDone, this);
    const bool stereo = mode_ == "stereo";
    info_sub_ = nh.subscribe<sensor_msgs::CameraInfo>(
        stereo ? "left/camera_info" : "rgb/camera_info", 5,
        [this](const sensor_msgs::CameraInfoConstPtr& m) { std::lock_guard<std::mutex> l(mu_); left_info_ = *m; });
    if (stereo)
      right_info_sub_ = nh.subscribe<sensor_msgs::CameraInfo>(
          "right/camera_info", 5,
          [this](const sensor_msgs::CameraInfoConstPtr& m) { std::lock_guard<std::mutex> l(mu_); right_info_ = *m; });
    first_.subscribe(nh, stereo ? "left/image_rect" : "rgb/image_rect", 10);
    second_.subscribe(nh, stereo ? "right/image_rect" : "depth/image_rect", 10);
    sync_ = std::make_unique<ImageSync>(first_, second_, 20);
    sync_->registerCallback(&AgentNodelet::onImages, this);
    timer_ = nh.createWallTimer(ros::WallDuration(0.2), &AgentNodelet::onTimer, this);
    NODELET_INFO("Agent %s: %s mode, config %s, spool %s", robot_.c_str(), mode_.c_str(),
                 config_file.c_str(), params_.uplink.buffer.dir.c_str());
  }

  /// Creates the pipeline at the first frame (the camera may come from camera_info).
  bool ensurePipeline() {
    if (pipeline_) return true;
    if (!camera_) {
      if (!left_info_ || (mode_ == "stereo" && !right_info_)) return false;
      auto K = intrinsicsFromInfo(*left_info_);
      if (!K.ok()) {
        NODELET_ERROR_THROTTLE(5.0, "Agent %s: %s", robot_.c_str(), K.error().c_str());
        return false;
      }
      camera_ = hermes::agent::AgentCamera{*K, right_info_ ? baselineFromInfo(*right_info_) : 0.0,
                                           hermes::SE3()};
    }
    auto p = hermes::agent::AgentPipeline::create(params_, robot_, *camera_);
    if (!p.ok()) {
      NODELET_FATAL("Agent %s: %s", robot_.c_str(), p.error().c_str());
      return false;
    }
    Status s = (*p)->attachUplink([this](std::uint32_t session, std::uint64_t seq,
                                         const std::vector<std::uint8_t>& frame) {
      hermes_msgs::EncodedSubmap m;
      m.header.stamp = ros::Time::now();
      m.agent_uuid = uuid_;
      m.session = session;
      m.seq = seq;
      m.data = frame;
      submap_pub_.publish(m);
    });
    if (!s) {
      NODELET_FATAL("Agent %s: %s", robot_.c_str(), s.error().c_str());
      return false;
    }
    (*p)->setUplinkClock([] { return ros::WallTime::now().toSec(); });
    pipeline_ = std::move(*p);
    uuid_ = hermes::toString(pipeline_->agentId());
    replayed_ = pipeline_->uplink()->buffer().pendingKeys();  // a previous run's backlog
    publishUplinkStatus();
    NODELET_INFO("Agent %s: uuid %s session %u", robot_.c_str(), uuid_.c_str(), pipeline_->session());
    return true;
  }

  using Status = hermes::Status;

  void onImages(const sensor_msgs::ImageConstPtr& a, const sensor_msgs::ImageConstPtr& b) {
    std::lock_guard<std::mutex> lock(mu_);
    if (!ensurePipeline()) return;
    hermes::CameraFrame frame;
    frame.stamp = a->header.stamp.toSec();
    auto left = greyImage(a);
    auto other = mode_ == "stereo" ? greyImage(b) : depthImage(b);
    if (!left.ok() || !other.ok()) {
      NODELET_ERROR_THROTTLE(2.0, "Agent %s: dropped frame: %s", robot_.c_str(),
                             (!left.ok() ? left.error() : other.error()).c_str());
      return;
    }
    frame.left = *left;
    (mode_ == "stereo" ? frame.right : frame.depth) = *other;
    auto r = pipeline_->feed(frame);
    noteSubmitted();
    if (!r.ok()) {
      NODELET_ERROR_THROTTLE(2.0, "Agent %s: %s", robot_.c_str(), r.error().c_str());
      return;
    }
    if (r->status != hermes::TrackingStatus::kOk) return;
    const hermes::SE3 T_W_B = pipeline_->trajectory().back().T_W_B;
    nav_msgs::Odometry odom;
    odom.header.stamp = a->header.stamp;
    odom.header.frame_id = robot_ + "/odom";
    odom.child_frame_id = robot_ + "/base_link";
    odom.pose.pose = toPose(T_W_B);
    odom_pub_.publish(odom);
    geometry_msgs::TransformStamped tf;
    tf.header = odom.header;
    tf.child_frame_id = odom.child_frame_id;
    tf.transform.translation.x = odom.pose.pose.position.x;
    tf.transform.translation.y = odom.pose.pose.position.y;
    tf.transform.translation.z = odom.pose.pose.position.z;
    tf.transform.rotation = odom.pose.pose.orientation;
    tf_.sendTransform(tf);
  }

  void onAck(const hermes_msgs::SubmapAckConstPtr& a) {
    std::lock_guard<std::mutex> lock(mu_);
    if (!pipeline_ || a->agent_uuid != uuid_) return;
    if (a->status == hermes_msgs::SubmapAck::REJECTED) {
      NODELET_ERROR_THROTTLE(2.0, "Agent %s: server rejected seq %lu: %s", robot_.c_str(),
                             static_cast<unsigned long>(a->seq), a->reason.c_str());
      return;  // kept in the spool; resent after the timeout
    }
    if (Status s = pipeline_->onAck(a->session, a->seq, ros::WallTime::now().toSec()); !s)
      NODELET_WARN_THROTTLE(2.0, "Agent %s: %s", robot_.c_str(), s.error().c_str());
  }

  void onDone(const std_msgs::EmptyConstPtr&) {
    std::lock_guard<std::mutex> lock(mu_);
    if (!pipeline_) return;
    pipeline_->flushWindow();
    noteSubmitted();
    done_ = true;
    publishUplinkStatus();
    NODELET_INFO("Agent %s: sequence done, %lld frames, lost %.1f %%, %lld submaps", robot_.c_str(),
                 static_cast<long long>(pipeline_->frames()), 100.0 * pipeline_->lostRate(),
                 static_cast<long long>(pipeline_->submapsSent()));
  }

  void onTimer(const ros::WallTimerEvent&) {
    std::lock_guard<std::mutex> lock(mu_);
    if (!pipeline_) return;
    const double now = ros::WallTime::now().toSec();
    pipeline_->pollUplink(now);
    // After the sequence no window step runs: a deferred window is retried here.
    if (done_ && pipeline_->hasCarriedWindow() &&
        now - last_retry_ >= params_.tracker.window.period_s) {
      last_retry_ = now;
      pipeline_->retryCarriedWindow(now);
      noteSubmitted();
    }
    if (now - last_heartbeat_ < 1.0) return;
    last_heartbeat_ = now;
    hermes_msgs::AgentHeartbeat hb;
    hb.header.stamp = ros::Time::now();
    hb.agent_uuid = uuid_;
    hb.session = pipeline_->session();
    hb.name = robot_;
    heartbeat_pub_.publish(hb);
    publishUplinkStatus();
  }

  /// Records a submap the last window step handed to the uplink (call after each step).
  void noteSubmitted() {
    const auto last = pipeline_->lastSubmitted();
    if (!last || (!created_.empty() && created_.back() == *last)) return;
    created_.push_back(*last);
    publishUplinkStatus();
  }

  void publishUplinkStatus() {
    using Keys = std::vector<std::pair<std::uint32_t, std::uint64_t>>;
    auto keys = [](const Keys& k) {
      nlohmann::json a = nlohmann::json::array();
      for (const auto& [session, seq] : k) a.push_back({session, seq});
      return a;
    };
    const hermes::agent::UplinkSender& up = *pipeline_->uplink();
    const hermes::agent::WindowCounters& w = pipeline_->windows();
    nlohmann::json j;
    j["robot"] = robot_;
    j["uuid"] = uuid_;
    j["pid"] = static_cast<std::int64_t>(::getpid());  // tells restarted processes apart
    j["session"] = pipeline_->session();
    j["created"] = keys(created_);
    j["replayed"] = keys(replayed_);
    j["pending"] = keys(up.buffer().pendingKeys());
    j["windows"] = {{"total", w.windows}, {"submitted", w.sent}, {"deferred", w.deferred},
                    {"failed", w.failed}, {"refused", w.refused},
                    {"extended_keyframes", w.extended_keyframes}};
    j["sends"] = up.stats().sends;
    j["resends"] = up.stats().resends;
    j["acked"] = up.stats().acked;
    j["spool_pending_bytes"] = up.buffer().pendingBytes();
    j["spool_file_bytes"] = up.buffer().fileBytes();
    j["spool_cap_bytes"] = static_cast<std::int64_t>(params_.uplink.buffer.max_mbytes * 1e6);
    j["done"] = done_;
    std_msgs::String m;
    m.data = j.dump();
    uplink_status_pub_.publish(m);
  }

  std::mutex mu_;
  std::string robot_, mode_, uuid_;
  hermes::agent::AgentPipelineParams params_;
  std::optional<hermes::agent::AgentCamera> camera_;
  std::optional<sensor_msgs::CameraInfo> left_info_, right_info_;
  std::unique_ptr<hermes::agent::AgentPipeline> pipeline_;
  ros::Publisher odom_pub_, submap_pub_, heartbeat_pub_, uplink_status_pub_;
  std::vector<std::pair<std::uint32_t, std::uint64_t>> created_, replayed_;
  bool done_ = false;
  ros::Subscriber ack_sub_, done_sub_, info_sub_, right_info_sub_;
  ImageSub first_, second_;
  std::unique_ptr<ImageSync> sync_;
  tf2_ros::TransformBroadcaster tf_;
  ros::WallTimer timer_;
  double last_heartbeat_ = 0;
  double last_retry_ = 0;  ///< wall time of the last retry of a carried window
};

}  // namespace hermes_agent

PLUGINLIB_EXPORT_CLASS(hermes_agent::AgentNodelet, nodelet::Nodelet)
