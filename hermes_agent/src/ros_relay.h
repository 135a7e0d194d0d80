// The relay side of relaying over ROS topics (agent nodelet ~relay_for U1,U2;
// README "Relay robots on ROS"): the relay robot R subscribes /R/relay/submap
// and /R/relay/heartbeat, spools its relayed robots' submaps per origin on disk
// (RelayForwarder over RelaySpool), answers each spooled one on /R/relay/U/held
// (the hop acknowledgement), forwards them untouched to /hermes/submap paced
// by its coordinator (relay_split.h: relay.min_mbitps per relayed robot, re-split
// every system.server_period_s on the relay's own uplink estimate; a 50 ms wall
// timer), passes the server's acknowledgements and global poses of its origins
// on (/R/relay/U/submap_ack, /R/relay/U/global_pose) and heartbeats on to
// /hermes/heartbeat. The server's acknowledgements for U wait at R until a node
// in U's namespace (/U/..., as agent.launch runs it) subscribes: a lost one
// would leave the submap in U's spool, handed over, until R reconnects.
//
// Threads: the ROS callbacks and the timer may run on any spinner thread; the
// forwarder is thread-safe itself, the acknowledgements waiting per origin sit
// behind the relay's own mutex. `publish` (the agent's /hermes/submap) is
// called under the forwarder's lock and must not call back into the relay.
#pragma once

#include <hermes_msgs/AgentHeartbeat.h>
#include <hermes_msgs/EncodedSubmap.h>
#include <hermes_msgs/GlobalPose.h>
#include <hermes_msgs/SubmapAck.h>
#include <ros/ros.h>

#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "hermes/agent/relay_forwarder.h"
#include "hermes/core/config.h"

namespace hermes_agent {

class RosRelay {
 public:
  /// Publishes a relayed robot's frame (routing uuid, session, seq, bytes) to the server.
  using Publish = std::function<void(const std::string& uuid, std::uint32_t session,
                                     std::uint64_t seq, const std::vector<std::uint8_t>& frame)>;
  /// The relay's own uplink estimate [byte/s] at wall time `now`.
  using UplinkEstimate = std::function<double(double now)>;

  /// Opens the spool `spool_dir` for `origins` (relay.* and system.server_period_s
  /// from `config`). Nothing is subscribed or timed yet (start()).
  static hermes::Expected<std::unique_ptr<RosRelay>> open(const std::string& robot,
                                                          const std::vector<std::string>& origins,
                                                          const std::string& spool_dir,
                                                          const hermes::agent::UplinkParams& uplink,
                                                          const hermes::Config& config, Publish publish);
  /// Advertises the answers per origin, subscribes the relay's inbox and starts
  /// forwarding; `heartbeats`: the robot's /hermes/heartbeat publisher.
  void start(ros::NodeHandle& nh, ros::Publisher heartbeats, UplinkEstimate uplink);

  /// Stops the timer and the inbox (waits for a callback in progress): call
  /// before what the UplinkEstimate reads is destroyed.
  void stop();
  /// The server (a subscriber of /hermes/submap) connected: everything held goes again.
  void onServerSubscribed() { forwarder_->onReconnect(); }
  /// The relay's own submap went out (its stream's credibility evidence).
  void onOwnFrame(std::uint32_t session, std::uint64_t seq, const std::vector<std::uint8_t>& frame);
  /// A server acknowledgement: true when it was a relayed robot's (freed here
  /// unless refused, passed on); false: not for a relayed robot.
  bool takeAck(const hermes_msgs::SubmapAck& a);
  /// A global pose: true when it was a relayed robot's (passed on).
  bool takeGlobalPose(const hermes_msgs::GlobalPoseConstPtr& m);
  /// Per relayed robot: spool, pace and forwarding counters (uplink_status "relay_for").
  nlohmann::json status() const;

 private:
  /// Per relayed robot: its answer topics and the server acknowledgements
  /// waiting for it to listen (the map is made in start(), then only read).
  struct Out {
    ros::Publisher held, ack, global;
    std::vector<hermes_msgs::SubmapAck> waiting;  ///< under out_mu_
    int listening = 0;  ///< subscribers of `ack` in the robot's namespace
  };

  RosRelay() = default;
  void onSubmap(const hermes_msgs::EncodedSubmapConstPtr& m);
  void onHeartbeat(const hermes_msgs::AgentHeartbeatConstPtr& h);
  void onTimer(const ros::WallTimerEvent&);
  /// The server's acknowledgement goes to `origin` when it listens, else it waits.
  void passAck(const std::string& origin, const hermes_msgs::SubmapAck& a);
  /// A node subscribed to / left `origin`'s submap_ack (only the origin's own count).
  void onAckListener(const std::string& origin, const std::string& node, int change);
  /// Publishes the waiting acknowledgements of one origin if it listens (out_mu_ held).
  static void flushAcks(Out& out);

  std::string robot_, spool_dir_;
  double min_mbitps_ = 0;
  std::unique_ptr<hermes::agent::RelayForwarder> forwarder_;
  UplinkEstimate uplink_;
  ros::Publisher heartbeats_;
  std::map<std::string, Out> out_;
  std::mutex out_mu_;
  ros::Subscriber submap_sub_, heartbeat_sub_;
  ros::WallTimer timer_;  ///< last: stopped first
};

}  // namespace hermes_agent
