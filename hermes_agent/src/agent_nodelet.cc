// Agent nodelet: one robot. Takes camera images as a robot or a rosbag
// publishes them, pairs and converts them in the ROS-free core (CameraStream:
// ApproximateSync + CameraInput) and feeds hermes::agent::AgentPipeline
// (tracking, local mapping, 5-s windows, distillation, disk spool); its uplink
// goes to the server's topics.
//   in : stereo: left/image + right/image (sensor_msgs/Image; raw or rectified),
//        rgbd  : rgb/image + depth/image (16UC1 / 32FC1); remap them to the
//        robot's topics (agent.launch does). camera_info is read from the
//        image topics' siblings (<image topic's namespace>/camera_info) when no
//        ~camera and no ~dataset gives the calibration.
//        done (std_msgs/Empty): end of the sequence, send the last partial window
//        /hermes/submap_ack (acks for this agent's uuid)
//        /hermes/global_pose (the server's world <- odom for this agent's uuid and
//        session, after each merge; ROS transport)
//   out: odom (nav_msgs/Odometry, frame <robot>/odom, child <robot>/base_link:
//        the body frame of the calibration's T_B_C, i.e. the dataset's
//        ground-truth frame (EuRoC: IMU body; TUM: colour camera); stamped with
//        the image stamp), TF <robot>/odom -> <robot>/base_link,
//        once the server placed the robot: odom_global (nav_msgs/Odometry, frame
//        world, child <robot>/base_link: its odometry through the latest world <-
//        odom) and TF world -> <robot>/odom, both with the image stamp,
//        /hermes/submap, /hermes/heartbeat (1 Hz)
//        uplink_status (std_msgs/String JSON, latched; after every new submap and at
//        1 Hz): session, submaps created by this process, spool pending keys/bytes,
//        spool cap -- what the delivery tests count as "sent" -- and `frames`:
//        images received, pairs, frames tracked / lost, rejected per cause;
//        `threads`: local BA jobs, keyframes merged / skipped, windows queued
// Params (private; all read in one place, agent_node_params.h): robot (default:
// the namespace), camera (a name under config/cameras/ or a calibration file /
// folder: camera_calibration.h),
// mode (stereo|rgbd; default: the calibration's kind, else stereo),
// rectified (auto|true|false: stereo images rectified already; overrides
// camera_input.stereo_images), config (YAML, default config/hermes.yaml),
// dataset (folder played by the DatasetPlayer: camera and body<-camera from
// it), queue_size (per image topic, 30), spool_dir (default
// /tmp/hermes_spool/<robot>), clear_spool (false: unacked submaps of a
// previous run are resent), parallel (true: local BA and the window step run
// on the pipeline's worker threads, so tracking never waits for them; false:
// inside the image callback, as the offline runner does), timing_window
// (uplink_status timings over each stage's last N samples; default
// agent.timing_window, or 3000 when that is 0), auth (frames tagged
// with the robot's key; default: uplink.auth.enabled, agent.launch sets true),
// key_file (default: uplink.auth.key_file, ~/.config/hermes/keys/<robot>.key;
// missing or not private: the nodelet does not start). The uplink runs on
// wall time. Images are paired under one mutex, the pipeline's calls are made
// under another (its uplink thread calls the transport, which only publishes).
// Transport (~transport, default: the config's `transport`): ros = the /hermes/*
// topics above; mqtt = hermes/<robot>/submap, /ack, /heartbeat, /global_pose through the broker
// of the config's mqtt.* (~mqtt_host, ~mqtt_port override host and port;
// hermes_transport/mqtt_links.h): the link's events are handled by a 20 ms wall
// timer under the pipeline mutex, after the pipeline exists (acks kept by the
// broker for a previous run wait for it). An unreachable broker is reported and
// tried again with backoff; the spool keeps everything meanwhile.
// Relay robots (ROS transport only; README "Relay robots on ROS"): ~relay_via R
// sends this robot's submaps and heartbeats not to /hermes/* but to the relay
// robot R's topics /R/relay/submap and /R/relay/heartbeat, and takes its
// acknowledgements from R's topics for it (U = this robot): /R/relay/U/held (R
// spooled the submap: the hop acknowledgement, UplinkSender::onHandedOver),
// /R/relay/U/submap_ack (the server's, passed on; R keeps them while U does not
// listen) and /R/relay/U/global_pose. Always through R, even when the server is
// reachable (no fallback). When R connects (a node in R's namespace: R started
// or came back) everything unacknowledged is offered again (R answers what the
// server already acknowledged with that acknowledgement). ~relay_for "U1,U2"
// makes this robot the relay of U1 and U2 (ros_relay.h: spool per origin on
// disk, ~relay_spool_dir, default <spool_dir>.relay; paced forwarding to
// /hermes/submap; acknowledgements and global poses passed on); when a
// subscriber of /hermes/submap connects (the server started or came back) it
// sends everything held again.
// A relay reaches the server itself (~relay_via and ~relay_for together are
// refused: no chains).
#include <hermes_msgs/AgentHeartbeat.h>
#include <hermes_msgs/EncodedSubmap.h>
#include <hermes_msgs/GlobalPose.h>
#include <hermes_msgs/MapDown.h>
#include <hermes_msgs/MapDownAck.h>
#include <hermes_msgs/SubmapAck.h>
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>
#include <ros/ros.h>
#include <std_msgs/Empty.h>
#include <std_msgs/String.h>


#include <algorithm>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <optional>

#include <nlohmann/json.hpp>

#include "hermes/agent/agent_pipeline.h"
#include "hermes/agent/camera_stream.h"
#include "hermes/agent/run_config.h"
#include "hermes/agent/dataset_feed.h"
#include "hermes/core/frame_auth.h"
#include "hermes/transport/mqtt_links.h"
#include "agent_node_params.h"
#include "odom_publisher.h"
#include "ros_convert.h"
#include "ros_relay.h"
#include "uplink_status.h"

namespace hermes_agent {
namespace {

/// The camera_info topic beside an image topic (image_transport's convention).
std::string infoTopic(const std::string& image_topic) {
  const auto slash = image_topic.rfind('/');
  return (slash == std::string::npos ? std::string() : image_topic.substr(0, slash + 1)) +
         "camera_info";
}

}  // namespace

class AgentNodelet : public nodelet::Nodelet {
 private:
  using Status = hermes::Status;
  using CameraCalibration = hermes::CameraCalibration;

  ~AgentNodelet() override {
    if (relay_) relay_->stop();  // its timer reads the pipeline, destroyed before it
  }

  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    const AgentNodeParams np = AgentNodeParams::read(nh, getPrivateNodeHandle());
    robot_ = np.robot;
    mode_ = np.mode;
    queue_size_ = np.queue_size;
    const std::string& config_file = np.config_file;
    const std::string& dataset = np.dataset;
    const std::string& camera = np.camera;
    const std::string& rectified = np.rectified;
    if (Status s = np.validate(); !s) {
      NODELET_FATAL("Agent %s: %s", robot_.c_str(), s.error().c_str());
      return;
    }
    auto config = hermes::loadConfig(config_file, {});
    hermes::agent::RunParams run;
    if (!config.ok() || !run.read(*config)) {
      NODELET_FATAL("Agent %s: config %s: %s", robot_.c_str(), config_file.c_str(),
                    config.ok() ? run.read(*config).error().c_str() : config.error().c_str());
      return;
    }
    params_ = run.agent;
    input_params_ = run.camera_input;
    if (!setUpTransport(np, *config)) return;
    if (rectified != "auto") input_params_.stereo_images = rectified == "true" ? "rectified" : "raw";
    // Real time: tracking never waits for local BA or the window step (worker
    // threads, agent_threads.h); ~parallel false runs them inside the image
    // callback as the offline runner does.
    params_.threads.parallel = np.parallel;
    // uplink_status is summarised every second for hours: over a bounded window.
    params_.threads.timing_window =
        np.timing_window.value_or(params_.threads.timing_window > 0 ? params_.threads.timing_window : 3000);
    params_.uplink.buffer.dir = np.spool_dir.value_or("/tmp/hermes_spool/" + robot_);
    if (!readRelayParams(np)) return;
    // Frame authentication: ~auth (launch default true) and ~key_file override
    // uplink.auth.*; the key is checked now, not at the first frame.
    params_.uplink.auth.enabled = np.auth.value_or(params_.uplink.auth.enabled);
    if (!np.key_file.empty()) params_.uplink.auth.key_file = np.key_file;
    if (params_.uplink.auth.enabled) {
      const std::string path = params_.uplink.auth.keyFileFor(robot_);
      if (auto key = hermes::readKeyFile(path); !key) {
        NODELET_FATAL("Agent %s: %s (create it with ./hermes keys add %s, or launch with auth:=false)",
                      robot_.c_str(), key.error().c_str(), robot_.c_str());
        return;
      }
      NODELET_INFO("Agent %s: frames tagged with the key in %s", robot_.c_str(), path.c_str());
    } else {
      NODELET_WARN("Agent %s: frame authentication is OFF", robot_.c_str());
    }
    if (np.clear_spool) {  // tests and demos: start without the previous run's backlog, same session counter
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
      if (!relay_for_.empty()) {  // the relayed robots keep theirs and offer them again
        std::error_code ec;
        std::filesystem::remove_all(relay_spool_dir_, ec);
      }
    }
    // The calibration: a dataset folder, a camera file, or later camera_info.
    if (!dataset.empty() && !camera.empty())
      NODELET_WARN("Agent %s: ~camera '%s' ignored: the camera comes from ~dataset %s",
                   robot_.c_str(), camera.c_str(), dataset.c_str());
    if (!dataset.empty()) {
      auto ds = hermes::Dataset::open(dataset, run.dataset);
      if (!ds.ok()) {
        NODELET_FATAL("Agent %s: dataset %s: %s", robot_.c_str(), dataset.c_str(), ds.error().c_str());
        return;
      }
      calibration_ = hermes::datasetCalibration(**ds);
    } else if (!camera.empty()) {
      auto c = hermes::loadCameraCalibration(camera, std::string(HERMES_SOURCE_DIR) + "/config/cameras");
      if (!c.ok()) {
        NODELET_FATAL("Agent %s: ~camera: %s", robot_.c_str(), c.error().c_str());
        return;
      }
      calibration_ = *c;
    }
    if (calibration_) {
      const std::string kind =
          calibration_->kind == CameraCalibration::Kind::kStereo ? "stereo" : "rgbd";
      if (mode_.empty()) mode_ = kind;
      if (mode_ != kind) {
        NODELET_FATAL("Agent %s: ~mode is %s but the calibration is %s (%s)", robot_.c_str(),
                      mode_.c_str(), kind.c_str(), calibration_->summary().c_str());
        return;
      }
    }
    if (mode_.empty()) mode_ = "stereo";
    const bool stereo = mode_ == "stereo";
    topic_a_ = nh.resolveName(stereo ? "left/image" : "rgb/image");
    topic_b_ = nh.resolveName(stereo ? "right/image" : "depth/image");

    odom_.advertise(nh, robot_);
    uplink_status_pub_ = nh.advertise<std_msgs::String>("uplink_status", 20, true);
    if (mqtt_) {
      mqtt_timer_ = nh.createWallTimer(ros::WallDuration(0.02), &AgentNodelet::onMqtt, this);
    } else if (!relay_via_.empty()) {  // everything through the relay robot's topics
      const std::string r = "/" + relay_via_ + "/relay/";
      submap_pub_ = nh.advertise<hermes_msgs::EncodedSubmap>(
          r + "submap", 20, [this](const ros::SingleSubscriberPublisher& p) { onRelayConnected(p.getSubscriberName()); });
      heartbeat_pub_ = nh.advertise<hermes_msgs::AgentHeartbeat>(r + "heartbeat", 5);
      const std::string mine = r + robot_ + "/";  // R's topics for this robot
      ack_sub_ = nh.subscribe(mine + "submap_ack", 100, &AgentNodelet::onAck, this);
      held_sub_ = nh.subscribe(mine + "held", 100, &AgentNodelet::onHeld, this);
      global_sub_ = nh.subscribe(mine + "global_pose", 20, &AgentNodelet::onGlobalPose, this);
    } else {
      if (relay_for_.empty()) submap_pub_ = nh.advertise<hermes_msgs::EncodedSubmap>("/hermes/submap", 20);
      heartbeat_pub_ = nh.advertise<hermes_msgs::AgentHeartbeat>("/hermes/heartbeat", 5);
      ack_sub_ = nh.subscribe("/hermes/submap_ack", 100, &AgentNodelet::onAck, this);
      global_sub_ = nh.subscribe("/hermes/global_pose", 20, &AgentNodelet::onGlobalPose, this);
      down_sub_ = nh.subscribe("/hermes/map_down", 20, &AgentNodelet::onMapDown, this);
      down_ack_pub_ = nh.advertise<hermes_msgs::MapDownAck>("/hermes/map_down_ack", 20);
      if (!relay_for_.empty() && !startRelay(nh, *config)) return;
    }
    done_sub_ = nh.subscribe("done", 1, &AgentNodelet::onDone, this);
    if (calibration_) {
      if (!createStream(*calibration_)) return;
    } else {  // the camera comes from camera_info
      info_a_sub_ = nh.subscribe<sensor_msgs::CameraInfo>(
          infoTopic(topic_a_), 5, [this](const sensor_msgs::CameraInfoConstPtr& m) { onInfo(m, true); });
      if (stereo)
        info_b_sub_ = nh.subscribe<sensor_msgs::CameraInfo>(
            infoTopic(topic_b_), 5, [this](const sensor_msgs::CameraInfoConstPtr& m) { onInfo(m, false); });
    }
    ros::TransportHints hints;
    hints.tcpNoDelay();
    image_a_sub_ = nh.subscribe<sensor_msgs::Image>(
        topic_a_, queue_size_, [this](const sensor_msgs::ImageConstPtr& m) { onImage(m, true); },
        ros::VoidConstPtr(), hints);
    image_b_sub_ = nh.subscribe<sensor_msgs::Image>(
        topic_b_, queue_size_, [this](const sensor_msgs::ImageConstPtr& m) { onImage(m, false); },
        ros::VoidConstPtr(), hints);
    timer_ = nh.createWallTimer(ros::WallDuration(0.2), &AgentNodelet::onTimer, this);
    NODELET_INFO("Agent %s: %s mode from %s + %s, camera %s, config %s, spool %s", robot_.c_str(),
                 mode_.c_str(), topic_a_.c_str(), topic_b_.c_str(),
                 calibration_ ? calibration_->summary().c_str()
                              : ("from " + infoTopic(topic_a_) +
                                 (stereo ? " + " + infoTopic(topic_b_) : std::string())).c_str(),
                 config_file.c_str(), params_.uplink.buffer.dir.c_str());
  }

  /// ~transport / the config's transport; with mqtt, the link to the broker.
  bool setUpTransport(const AgentNodeParams& np, const hermes::Config& config) {
    hermes::transport::TransportParams tp;
    if (hermes::Status s = tp.read(config); !s) {
      NODELET_FATAL("Agent %s: config: %s", robot_.c_str(), s.error().c_str());
      return false;
    }
    if (!np.transport.empty()) tp.kind = np.transport;
    tp.mqtt.host = np.mqtt_host.value_or(tp.mqtt.host);
    tp.mqtt.port = np.mqtt_port.value_or(tp.mqtt.port);
    if (hermes::Status s = tp.validate(); !s) {
      NODELET_FATAL("Agent %s: ~transport / ~mqtt_*: %s", robot_.c_str(), s.error().c_str());
      return false;
    }
    if (!tp.mqttEnabled()) return true;
    auto link = hermes::transport::MqttAgentLink::create(tp.mqtt, robot_, hermes::agentUuid(robot_));
    if (!link) {
      NODELET_FATAL("Agent %s: %s", robot_.c_str(), link.error().c_str());
      return false;
    }
    mqtt_ = std::move(*link);
    mqtt_->client().start();
    if (hermes::Status s = mqtt_->client().waitConnected(tp.mqtt.connect_timeout_s); !s)
      NODELET_ERROR("Agent %s: %s; submaps wait in the spool", robot_.c_str(), s.error().c_str());
    else
      NODELET_INFO("Agent %s: uplink over MQTT, broker %s, client id %s", robot_.c_str(),
                   mqtt_->client().broker().c_str(), mqtt_->client().clientId().c_str());
    return true;
  }

  /// ~relay_via / ~relay_for / ~relay_spool_dir, checked (ROS transport only, no chains).
  bool readRelayParams(const AgentNodeParams& np) {
    relay_via_ = np.relay_via;
    relay_spool_dir_ = np.relay_spool_dir.value_or(params_.uplink.buffer.dir + ".relay");
    auto origins = hermes::agent::parseRobotList(np.relay_for);
    Status ok = origins.ok() ? Status::Ok() : Status(hermes::Error{"~relay_for: " + origins.error()});
    if (ok && !relay_via_.empty())
      if (Status s = hermes::agent::checkRobotName(relay_via_); !s) ok = hermes::Error{"~relay_via: " + s.error()};
    const bool relays = ok && !origins->empty();
    if (ok && !relay_via_.empty() && relays)
      ok = hermes::Error{"~relay_via and ~relay_for together: a relay reaches the server itself (no relay chains)"};
    if (ok && (relay_via_ == robot_ || (relays && std::count(origins->begin(), origins->end(), robot_))))
      ok = hermes::Error{"a robot cannot relay for itself"};
    if (ok && mqtt_ && (!relay_via_.empty() || relays))
      ok = hermes::Error{"relaying runs over ROS topics: ~relay_via / ~relay_for need ~transport ros"};
    if (!ok) {
      NODELET_FATAL("Agent %s: %s", robot_.c_str(), ok.error().c_str());
      return false;
    }
    relay_for_ = *origins;
    return true;
  }

  /// ~relay_for: the spool per origin, /hermes/submap (the server subscribing
  /// makes the relay send all it holds), the relay's topics (ros_relay.h).
  bool startRelay(ros::NodeHandle& nh, const hermes::Config& config) {
    auto relay = RosRelay::open(
        robot_, relay_for_, relay_spool_dir_, params_.uplink, config,
        [this](const std::string& uuid, std::uint32_t session, std::uint64_t seq,
               const std::vector<std::uint8_t>& frame) { publishSubmap(uuid, session, seq, frame); });
    if (!relay) {
      NODELET_FATAL("Agent %s: %s", robot_.c_str(), relay.error().c_str());
      return false;
    }
    relay_ = std::move(*relay);
    submap_pub_ = nh.advertise<hermes_msgs::EncodedSubmap>(
        "/hermes/submap", 20, [this](const ros::SingleSubscriberPublisher&) { relay_->onServerSubscribed(); });
    const double initial_Bps = params_.uplink.monitor.initial_bps;  // before the relay's own first submap
    relay_->start(nh, heartbeat_pub_, [this, initial_Bps](double now) {
      std::lock_guard<std::mutex> lock(mu_);  // released before the forwarder polls
      if (!pipeline_) return initial_Bps;
      return pipeline_->withUplink([now](const hermes::agent::UplinkSender* up) {
        return up ? up->monitor().estimate(now) : 0.0;
      });
    });
    return true;
  }

  /// A frame on submap_pub_: /hermes/submap, or the relay's topic with ~relay_via.
  void publishSubmap(const std::string& uuid, std::uint32_t session, std::uint64_t seq,
                     const std::vector<std::uint8_t>& frame) {
    hermes_msgs::EncodedSubmap m;
    m.header.stamp = ros::Time::now();
    m.agent_uuid = uuid;
    m.session = session;
    m.seq = seq;
    m.data = frame;
    submap_pub_.publish(m);
  }

  /// Origin: the relay robot (a node in its namespace, as agent.launch runs it;
  /// not an observer) connected to our submaps (started, or back): everything
  /// unacknowledged is offered again.
  void onRelayConnected(const std::string& node) {
    if (node.rfind("/" + relay_via_ + "/", 0) != 0) return;
    std::lock_guard<std::mutex> lock(mu_);
    NODELET_INFO("Agent %s: relay %s connected%s", robot_.c_str(), relay_via_.c_str(),
                 pipeline_ ? "; everything unacknowledged is offered again" : "");
    if (pipeline_) pipeline_->onUplinkReconnect();
  }

  /// Origin: the relay holds our submap durably (hop acknowledgement).
  void onHeld(const hermes_msgs::SubmapAckConstPtr& a) {
    std::lock_guard<std::mutex> lock(mu_);
    if (!pipeline_ || a->agent_uuid != uuid_) return;
    ++hop_acks_;
    if (Status s = pipeline_->onHandedOver(a->session, a->seq, ros::WallTime::now().toSec()); !s)
      NODELET_WARN_THROTTLE(2.0, "Agent %s: %s", robot_.c_str(), s.error().c_str());
  }

  /// MQTT: acknowledgements, reconnections and problems since the last tick.
  void onMqtt(const ros::WallTimerEvent&) {
    std::lock_guard<std::mutex> lock(mu_);
    if (!pipeline_) return;  // the events wait in the link's inbox
    hermes::transport::AgentLinkEvents ev = mqtt_->poll();
    for (const std::string& p : ev.problems) NODELET_WARN_THROTTLE(2.0, "Agent %s: mqtt: %s", robot_.c_str(), p.c_str());
    if (ev.connected_now)
      NODELET_INFO("Agent %s: connected to MQTT broker %s%s", robot_.c_str(), mqtt_->client().broker().c_str(),
                   ev.resend_all ? "; everything unacknowledged is sent again" : " (session resumed)");
    if (ev.resend_all) pipeline_->onUplinkReconnect();
    for (const hermes::transport::AckMessage& a : ev.acks)
      handleAck(!a.acknowledges(), a.reason_code == hermes_msgs::SubmapAck::REASON_QUOTA, a.session, a.seq,
                a.reason);
    for (const hermes::GlobalPoseUpdate& u : ev.global_poses) takeGlobalPose(u, "mqtt global_pose");
  }

  /// The core's pairing and conversion for `calib` (call with stream_mu_ held or
  /// before the subscriptions exist).
  bool createStream(const CameraCalibration& calib) {
    auto s = hermes::agent::CameraStream::create(calib, input_params_, topic_a_, topic_b_);
    if (!s.ok()) {
      NODELET_FATAL("Agent %s: camera: %s", robot_.c_str(), s.error().c_str());
      return false;
    }
    stream_ = std::make_unique<hermes::agent::CameraStream>(std::move(*s));
    NODELET_INFO("Agent %s: camera input: %s", robot_.c_str(), stream_->input().summary().c_str());
    return true;
  }

  void onInfo(const sensor_msgs::CameraInfoConstPtr& m, bool first) {
    std::lock_guard<std::mutex> lock(stream_mu_);
    if (stream_) return;
    (first ? info_a_ : info_b_) = *m;
    const bool stereo = mode_ == "stereo";
    if (!info_a_ || (stereo && !info_b_)) return;
    // ROS drivers publish 16UC1 depth in millimetres.
    const double scale = input_params_.depth_scale_16u > 0 ? input_params_.depth_scale_16u : 1000.0;
    const hermes::CameraInfoMessage a = cameraInfoMessage(*info_a_);
    const std::optional<hermes::CameraInfoMessage> b =
        stereo ? std::optional(cameraInfoMessage(*info_b_)) : std::nullopt;
    auto calib = hermes::calibrationFromCameraInfo(a, infoTopic(topic_a_), b ? &*b : nullptr,
                                                   infoTopic(topic_b_), scale);
    if (!calib.ok()) {
      if (calib.error() != info_error_)  // each distinct problem once
        NODELET_ERROR("Agent %s: camera_info unusable (images are dropped until it is fixed): %s",
                      robot_.c_str(), calib.error().c_str());
      info_error_ = calib.error();
      return;
    }
    auto s = hermes::agent::CameraStream::create(*calib, input_params_, topic_a_, topic_b_);
    if (!s.ok()) {
      if (s.error() != info_error_)
        NODELET_ERROR("Agent %s: camera_info unusable: %s", robot_.c_str(), s.error().c_str());
      info_error_ = s.error();
      return;
    }
    stream_ = std::make_unique<hermes::agent::CameraStream>(std::move(*s));
    NODELET_INFO("Agent %s: camera from camera_info: %s; input: %s", robot_.c_str(),
                 calib->summary().c_str(), stream_->input().summary().c_str());
  }

  void onImage(const sensor_msgs::ImageConstPtr& m, bool first) {
    {
      std::lock_guard<std::mutex> lock(stream_mu_);
      ++(first ? received_a_ : received_b_);
      if (!stream_) {  // camera_info may just be a few messages late: complain after 10 images
        if (++no_camera_ >= 10) {
          const std::string infos =
              infoTopic(topic_a_) + (mode_ == "stereo" ? " + " + infoTopic(topic_b_) : "");
          NODELET_ERROR_THROTTLE(10.0, "Agent %s: no usable camera: ~camera and ~dataset are not "
                                 "set and %s gave no usable camera_info%s; %lld images dropped",
                                 robot_.c_str(), infos.c_str(),
                                 info_error_.empty() ? "" : (" (" + info_error_ + ")").c_str(),
                                 static_cast<long long>(no_camera_));
        }
        return;
      }
      auto image = inputImage(m);
      if (!image.ok()) {
        if (++malformed_ == 1)
          NODELET_ERROR("Agent %s: malformed message on %s: %s", robot_.c_str(),
                        (first ? topic_a_ : topic_b_).c_str(), image.error().c_str());
        return;
      }
      if (first) {
        exact_stamps_[image->stamp] = m->header.stamp;  // odom carries the image's own stamp
        while (exact_stamps_.size() > 1000) exact_stamps_.erase(exact_stamps_.begin());
        stream_->pushA(std::move(*image));
      } else {
        stream_->pushB(std::move(*image));
      }
      logProblems();
    }
    trackReadyFrames();
  }

  /// Logs each new input problem once (the counts are in uplink_status).
  void logProblems() {
    for (const std::string& p : stream_->problems())
      NODELET_ERROR("Agent %s: input %s (each cause is logged once; counts in uplink_status)",
                    robot_.c_str(), p.c_str());
  }

  /// Tracks every converted frame waiting, in stamp order (one caller at a time).
  void trackReadyFrames() {
    std::lock_guard<std::mutex> lock(mu_);
    for (;;) {
      std::optional<hermes::CameraFrame> frame;
      ros::Time stamp;
      {
        std::lock_guard<std::mutex> l(stream_mu_);
        frame = stream_->next();
        logProblems();
        if (!frame) return;
        // The header stamp exactly (the core's seconds lose nanoseconds); older ones go.
        auto it = exact_stamps_.find(frame->stamp);
        stamp = it != exact_stamps_.end() ? it->second : ros::Time(frame->stamp);
        exact_stamps_.erase(exact_stamps_.begin(), exact_stamps_.upper_bound(frame->stamp));
      }
      track(*frame, stamp);
    }
  }

  /// Creates the pipeline at the first frame.
  bool ensurePipeline() {
    if (pipeline_) return true;
    auto p = hermes::agent::AgentPipeline::create(params_, robot_, stream_->camera());
    if (!p.ok()) {
      NODELET_FATAL("Agent %s: %s", robot_.c_str(), p.error().c_str());
      return false;
    }
    Status s = (*p)->attachUplink([this](std::uint32_t session, std::uint64_t seq,
                                         const std::vector<std::uint8_t>& frame) {
      if (mqtt_) {  // offline: refused, the spool sends it again after the reconnect
        if (Status sent = mqtt_->sendSubmap(frame); !sent)
          NODELET_WARN_THROTTLE(5.0, "Agent %s: seq %lu not sent: %s", robot_.c_str(),
                                static_cast<unsigned long>(seq), sent.error().c_str());
        return;
      }
      if (relay_)  // the relay's own stream: its credibility evidence (relay lock after the uplink's)
        relay_->onOwnFrame(session, seq, frame);
      publishSubmap(uuid_, session, seq, frame);
    });
    if (!s) {
      NODELET_FATAL("Agent %s: %s", robot_.c_str(), s.error().c_str());
      return false;
    }
    (*p)->setUplinkClock([] { return ros::WallTime::now().toSec(); });
    pipeline_ = std::move(*p);
    uuid_ = hermes::toString(pipeline_->agentId());
    replayed_ = pipeline_->withUplink(  // a previous run's backlog
        [](const hermes::agent::UplinkSender* up) { return up->buffer().pendingKeys(); });
    publishUplinkStatus();
    NODELET_INFO("Agent %s: uuid %s session %u", robot_.c_str(), uuid_.c_str(), pipeline_->session());
    return true;
  }

  void track(const hermes::CameraFrame& frame, const ros::Time& stamp) {
    if (!ensurePipeline()) return;
    auto r = pipeline_->feed(frame);
    noteSubmitted();
    if (!r.ok()) {
      ++feed_errors_;
      NODELET_ERROR_THROTTLE(2.0, "Agent %s: %s", robot_.c_str(), r.error().c_str());
      return;
    }
    if (r->status != hermes::TrackingStatus::kOk) return;
    ++tracked_;
    odom_.publish(pipeline_->trajectory().back().T_W_B, pipeline_->globalPose(), stamp);
  }

  void onGlobalPose(const hermes_msgs::GlobalPoseConstPtr& m) {
    if (relay_ && relay_->takeGlobalPose(m)) return;  // a relayed robot's (never this robot's own)
    std::lock_guard<std::mutex> lock(mu_);
    if (!pipeline_ || m->agent_uuid != uuid_) return;
    hermes::GlobalPoseUpdate u;
    u.session = m->session;
    u.keyframe_stamp = m->keyframe_stamp;
    u.keyframes = m->keyframes;
    const auto& tr = m->world_from_odom;
    u.T_W_O = hermes::SE3(hermes::Quat(tr.rotation.w, tr.rotation.x, tr.rotation.y, tr.rotation.z),
                          hermes::Vec3(tr.translation.x, tr.translation.y, tr.translation.z));
    takeGlobalPose(u, "/hermes/global_pose");
  }

  /// The server's downlink (server.downlink): into the pipeline's borrowed map, acknowledged.
  void onMapDown(const hermes_msgs::MapDownConstPtr& m) {
    std::lock_guard<std::mutex> lock(mu_);
    if (!pipeline_ || m->agent_uuid != uuid_) return;
    auto ack = pipeline_->onMapDown(m->data.data(), m->data.size(), ros::WallTime::now().toSec());
    if (!ack) {
      NODELET_WARN_THROTTLE(5.0, "Agent %s: /hermes/map_down: %s", robot_.c_str(), ack.error().c_str());
      return;
    }
    hermes_msgs::MapDownAck a;
    a.header.stamp = ros::Time::now();
    a.agent_uuid = uuid_;
    a.epoch = ack->epoch;
    a.seq = ack->seq;
    down_ack_pub_.publish(a);
  }

  /// This robot's world <- odom (ROS or MQTT; call with mu_ held and the pipeline made).
  void takeGlobalPose(const hermes::GlobalPoseUpdate& u, const char* source) {
    if (hermes::Status s = u.validate(); !s) {
      NODELET_WARN_THROTTLE(5.0, "Agent %s: %s: %s", robot_.c_str(), source, s.error().c_str());
      return;
    }
    if (pipeline_->onGlobalPose(u, ros::WallTime::now().toSec()) && !placed_) {
      placed_ = true;
      NODELET_INFO("Agent %s: placed in the global map (%llu merged keyframes)", robot_.c_str(),
                   static_cast<unsigned long long>(u.keyframes));
    }
  }

  void onAck(const hermes_msgs::SubmapAckConstPtr& a) {
    if (relay_ && relay_->takeAck(*a)) return;  // a relayed robot's (never this robot's own)
    std::lock_guard<std::mutex> lock(mu_);
    if (!pipeline_ || a->agent_uuid != uuid_) return;
    handleAck(a->status == hermes_msgs::SubmapAck::REJECTED,
              a->reason_code == hermes_msgs::SubmapAck::REASON_QUOTA, a->session, a->seq, a->reason);
  }

  /// One acknowledgement of this robot's (ROS or MQTT; call with mu_ held).
  void handleAck(bool rejected, bool quota, std::uint32_t session, std::uint64_t seq,
                 const std::string& reason) {
    if (rejected) {
      // Kept in the spool and resent after the timeout. A quota refusal is the
      // server's back-pressure, not an error; the others (bad tag, unknown
      // robot, ...) may also answer someone else's frame under this uuid.
      if (quota)
        NODELET_INFO_THROTTLE(5.0, "Agent %s: server busy, seq %lu resent later: %s",
                              robot_.c_str(), static_cast<unsigned long>(seq), reason.c_str());
      else
        NODELET_ERROR_THROTTLE(2.0, "Agent %s: server rejected seq %lu: %s", robot_.c_str(),
                               static_cast<unsigned long>(seq), reason.c_str());
      return;
    }
    if (Status s = pipeline_->onAck(session, seq, ros::WallTime::now().toSec()); !s)
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
    // The window worker may submit after the call that queued its step (a retry
    // after the last frame): recorded here, or uplink_status would never list it.
    noteSubmitted();
    // After the sequence no window step runs: a deferred window is retried here.
    if (done_ && pipeline_->hasCarriedWindow() &&
        now - last_retry_ >= params_.tracker.window.period_s) {
      last_retry_ = now;
      pipeline_->retryCarriedWindow(now);
      noteSubmitted();
    }
    if (now - last_heartbeat_ < 1.0) return;
    last_heartbeat_ = now;
    if (mqtt_) {
      const auto last = pipeline_->lastSubmitted();
      mqtt_->sendHeartbeat(pipeline_->session(), last && last->first == pipeline_->session() ? last->second + 1 : 0);
      publishUplinkStatus();
      return;
    }
    hermes_msgs::AgentHeartbeat hb;
    hb.header.stamp = ros::Time::now();
    hb.agent_uuid = uuid_;
    hb.session = pipeline_->session();
    hb.name = robot_;
    heartbeat_pub_.publish(hb);
    publishUplinkStatus();
  }

  /// Records every submap handed to the uplink since the last call (a step can
  /// send two: a carried window and the new one; call after each step).
  void noteSubmitted() {
    const auto fresh = pipeline_->submittedFrom(created_.size());
    if (fresh.empty()) return;
    created_.insert(created_.end(), fresh.begin(), fresh.end());
    publishUplinkStatus();
  }

  /// What happened to the images so far (uplink_status "frames").
  nlohmann::json frameCounts() {
    nlohmann::json f;
    std::lock_guard<std::mutex> l(stream_mu_);
    f["received"] = {{topic_a_, received_a_}, {topic_b_, received_b_}};
    f["dropped_no_camera"] = no_camera_;
    f["dropped_malformed"] = malformed_;
    if (stream_) {
      const hermes::agent::StreamCounters c = stream_->counters();
      f["paired"] = c.paired;
      f["unpaired"] = {{topic_a_, c.unpaired_a}, {topic_b_, c.unpaired_b}};
      f["out_of_order"] = c.out_of_order;
      f["converted"] = c.converted;
      f["rejected"] = c.rejected;
      f["rejected_by_cause"] = c.rejected_by_cause;
    }
    f["fed"] = pipeline_ ? pipeline_->frames() : 0;
    f["tracked"] = tracked_;
    f["lost"] = pipeline_ ? pipeline_->lostFrames() : 0;
    f["feed_errors"] = feed_errors_;
    return f;
  }

  void publishUplinkStatus() {
    UplinkStatusContext c;
    c.robot = robot_;
    c.uuid = uuid_;
    c.created = &created_;
    c.replayed = &replayed_;
    c.spool_cap_bytes = static_cast<std::int64_t>(params_.uplink.buffer.max_mbytes * 1e6);
    c.done = done_;
    c.relay_via = relay_via_;
    c.hop_acks = hop_acks_;
    c.relay = relay_.get();
    c.mqtt = mqtt_.get();
    c.frames = frameCounts();
    std_msgs::String m;
    m.data = uplinkStatusJson(*pipeline_, c).dump();
    uplink_status_pub_.publish(m);
  }

  std::mutex mu_;         ///< the pipeline, uplink bookkeeping
  std::mutex stream_mu_;  ///< stream_, camera_info, image counters (taken after mu_, never before)
  std::string robot_, mode_, uuid_;
  std::string topic_a_, topic_b_;  ///< resolved image topics (left|rgb, right|depth)
  int queue_size_ = 30;
  hermes::agent::AgentPipelineParams params_;
  hermes::agent::CameraInputParams input_params_;
  std::optional<CameraCalibration> calibration_;  ///< from ~dataset or ~camera
  std::optional<sensor_msgs::CameraInfo> info_a_, info_b_;
  std::string info_error_;  ///< the last camera_info problem (logged when it changes)
  std::unique_ptr<hermes::agent::CameraStream> stream_;
  std::map<double, ros::Time> exact_stamps_;  ///< left / colour header stamps by seconds
  /// Set: transport mqtt. Declared before the pipeline, whose uplink thread uses it
  /// until the pipeline is gone.
  std::unique_ptr<hermes::transport::MqttAgentLink> mqtt_;
  // Relaying (ROS transport). relay_via_: this robot's relay; relay_: this robot
  // relays relay_for_ (thread-safe itself; taken after mu_ or the uplink lock,
  // never before). Declared before the pipeline, whose uplink thread uses it.
  std::string relay_via_, relay_spool_dir_;
  std::vector<std::string> relay_for_;
  std::unique_ptr<RosRelay> relay_;
  std::size_t hop_acks_ = 0;  ///< hop acknowledgements of the relay (relay_via_)
  std::unique_ptr<hermes::agent::AgentPipeline> pipeline_;
  std::int64_t received_a_ = 0, received_b_ = 0, no_camera_ = 0, malformed_ = 0;
  std::int64_t tracked_ = 0, feed_errors_ = 0;
  OdomPublisher odom_;
  ros::Publisher submap_pub_, heartbeat_pub_, uplink_status_pub_;
  ros::Subscriber global_sub_, down_sub_;
  ros::Publisher down_ack_pub_;
  bool placed_ = false;  ///< the first world <- odom was taken (logged once)
  std::vector<std::pair<std::uint32_t, std::uint64_t>> created_, replayed_;
  bool done_ = false;
  ros::Subscriber ack_sub_, done_sub_, info_a_sub_, info_b_sub_, image_a_sub_, image_b_sub_;
  ros::WallTimer timer_, mqtt_timer_;
  ros::Subscriber held_sub_;
  double last_heartbeat_ = 0;
  double last_retry_ = 0;  ///< wall time of the last retry of a carried window
};

}  // namespace hermes_agent

PLUGINLIB_EXPORT_CLASS(hermes_agent::AgentNodelet, nodelet::Nodelet)
