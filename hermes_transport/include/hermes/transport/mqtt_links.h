// The two ends of the MQTT transport (topics and payloads: mqtt_messages.h).
//
// MqttAgentLink (one robot): publishes its submap frames and heartbeats, receives
// its acknowledgements. It is the UplinkSender's transport; the sender's spool
// stays the source of truth -- QoS 2 is not trusted across broker restarts. When
// a connection comes up without the broker's copy of our session (a broker that
// restarted without persistence, or expired it), or after publishes were refused
// while offline, poll() says `resend_all`: the owner calls
// UplinkSender::onReconnect() and everything unacknowledged goes out again (the
// server drops what it already has).
//
// It also receives the robot's place in the world (global_pose, after merges).
//
// MqttServerLink (the edge server): receives every robot's frames and
// heartbeats, publishes each frame's acknowledgement to that robot's ack topic
// and, after merges, each anchored robot's world <- odom (sendGlobalPose).
// A frame claims the identity of its topic: its uuid must be agentUuid(<agent>)
// (the ReceiveCode::kRoutingMismatch check), so a robot cannot be acknowledged
// for another's frames. Malformed payloads are answered (frames, with the reason)
// or reported (heartbeats) and never touch other robots.
//
// Both are thin: no thread of their own beyond the client's (mqtt_client.h);
// the owner calls poll() from the thread that owns the sender / the server.
#pragma once

#include <atomic>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "hermes/core/delivery.h"
#include "hermes/transport/mqtt_client.h"
#include "hermes/transport/mqtt_global_pose.h"
#include "hermes/transport/mqtt_messages.h"

namespace hermes::transport {

struct AgentLinkEvents {
  std::vector<AckMessage> acks;  ///< this robot's acknowledgements, in arrival order
  /// World <- odom updates for this robot, in arrival order (GlobalPoseState::update
  /// keeps the newest of its current session).
  std::vector<GlobalPoseUpdate> global_poses;
  bool resend_all = false;       ///< see above: call UplinkSender::onReconnect()
  bool connected_now = false;    ///< a connection came up in this batch
  std::vector<std::string> problems;  ///< lost connections, malformed or foreign payloads, in words
};

class MqttAgentLink {
 public:
  /// Client id "<prefix>-agent-<robot>"; subscribes hermes/<robot>/ack (QoS 2)
  /// and hermes/<robot>/global_pose (QoS 0).
  /// `uuid` is the robot's (acks for other uuids are reported, not used).
  static Expected<std::unique_ptr<MqttAgentLink>> create(const MqttParams& params,
                                                         const std::string& robot, const Uuid& uuid);
  MqttClient& client() { return *client_; }

  /// Publishes one wire frame on hermes/<robot>/submap (QoS 2). An error (offline)
  /// is not fatal: the frame stays in the spool and goes out again after a
  /// reconnect or the resend timeout.
  Status sendSubmap(const std::vector<std::uint8_t>& frame);
  /// Publishes a heartbeat on hermes/<robot>/heartbeat (QoS 0).
  Status sendHeartbeat(std::uint32_t session, std::uint64_t next_seq);
  /// What arrived since the last call.
  AgentLinkEvents poll();

  const std::string& robot() const { return robot_; }
  std::size_t malformed() const { return malformed_; }

 private:
  MqttAgentLink(std::string robot, const Uuid& uuid, std::unique_ptr<MqttClient> client)
      : robot_(std::move(robot)), uuid_(uuid), client_(std::move(client)) {}
  std::string robot_;
  Uuid uuid_;
  std::unique_ptr<MqttClient> client_;
  std::atomic<bool> refused_offline_{false};
  std::size_t malformed_ = 0;
};

struct IncomingFrame {
  std::string agent;  ///< the topic's robot name
  std::vector<std::uint8_t> frame;
};

struct ServerLinkEvents {
  std::vector<IncomingFrame> frames;  ///< in arrival order
  std::vector<HeartbeatMessage> heartbeats;  ///< name checked against the topic
  std::vector<std::string> problems;  ///< malformed heartbeats, bad topics, lost connections
};

/// The acknowledgement of a receive() result, for the frame's robot.
AckMessage ackFor(const ReceiveResult& result, const Uuid& agent);

class MqttServerLink {
 public:
  using Receive = std::function<ReceiveResult(const std::uint8_t* data, std::size_t size,
                                              const SubmapHeader* claimed)>;

  /// Client id "<prefix>-server"; subscribes hermes/+/submap (QoS 2) and
  /// hermes/+/heartbeat (QoS 0).
  static Expected<std::unique_ptr<MqttServerLink>> create(const MqttParams& params);
  MqttClient& client() { return *client_; }

  ServerLinkEvents poll();
  /// Hands `in` to `receive` (Server::onFrame, SubmapReceiver::receive) with the
  /// topic's identity as the claimed routing, and publishes the acknowledgement
  /// (rejections too, with the reason). Returns the result; an ack that cannot be
  /// published is counted in unsentAcks() (the robot resends, the server acks again).
  ReceiveResult handle(const IncomingFrame& in, const Receive& receive);
  Status sendAck(const std::string& agent, const AckMessage& ack);
  /// Publishes `msg` on hermes/<agent>/global_pose (QoS 0; the next merge sends a
  /// newer one, so a lost one costs nothing).
  Status sendGlobalPose(const std::string& agent, const GlobalPoseMessage& msg);
  std::size_t unsentAcks() const { return unsent_acks_; }

 private:
  explicit MqttServerLink(std::unique_ptr<MqttClient> client) : client_(std::move(client)) {}
  std::unique_ptr<MqttClient> client_;
  std::size_t unsent_acks_ = 0;
};

}  // namespace hermes::transport
