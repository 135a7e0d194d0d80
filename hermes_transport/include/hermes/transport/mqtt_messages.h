// What travels over MQTT between agents and the server, and on which topics.
//
// Topics (one level per robot; `<agent>` is the robot name):
//   hermes/<agent>/submap     agent -> server, QoS 2: one wire frame (wire_format.h), as is
//   hermes/<agent>/ack        server -> agent, QoS 2: AckMessage, for every frame (rejections too)
//   hermes/<agent>/heartbeat  agent -> server, QoS 0: HeartbeatMessage, 1 Hz. QoS 0 on
//                             purpose: a heartbeat queued for an absent server is stale
//                             by the time it arrives (and mosquitto does not queue QoS 0
//                             for offline persistent sessions).
//   hermes/<agent>/global_pose server -> agent, QoS 0: the robot's world <- odom
//                             after merges (mqtt_global_pose.h)
// Robot names are 1..64 characters of [A-Za-z0-9_.-] (no MQTT wildcards or level
// separators, so a name is exactly one topic level).
//
// Encodings (all integers little-endian; the decoders accept exactly these sizes):
//
// AckMessage (42 + n bytes)
//   offset size  field
//        0    4  magic "HACK"
//        4    1  version (1)
//        5    1  status: 0 accepted, 1 duplicate (acknowledged, not applied), 2 rejected
//        6    1  reason_code (hermes::ReceiveCode, submap_receiver.h: 0..9); accepted
//                goes with 0, duplicate with 1 (replay) or 2 (stale), rejected with 3..9
//        7    1  reserved, 0
//        8   16  agent uuid (the frame's; the robot checks it is its own)
//       24    4  session
//       28    8  seq
//       36    4  robot id assigned by the server
//       40    2  n = reason length, <= 1024
//       42    n  reason (text; empty when accepted)
//
// HeartbeatMessage (38 + n bytes)
//        0    4  magic "HHBT"
//        4    1  version (1)
//        5    3  reserved, 0
//        8   16  agent uuid
//       24    4  session
//       28    8  next_seq (the next sequence number the agent will send)
//       36    2  n = name length, 1..64
//       38    n  robot name (the topic's <agent>: the server checks they agree)
//
// Decoding errors start with "mqtt ack: " / "mqtt heartbeat: " and name the field
// and its offset.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "hermes/core/map_types.h"
#include "hermes/core/status.h"

namespace hermes::transport {

enum class MqttChannel { kSubmap, kAck, kHeartbeat, kGlobalPose };
/// "submap", "ack", "heartbeat", "global_pose".
const char* toString(MqttChannel channel);

constexpr std::size_t kMaxAgentNameBytes = 64;
constexpr std::size_t kMaxAckReasonBytes = 1024;
/// hermes::ReceiveCode has this many codes (a static_assert in mqtt_server_link.cc).
constexpr std::uint8_t kAckReasonCodes = 10;

/// Empty when `name` can be a robot's topic level, else why not.
Status validateAgentName(const std::string& name);
/// "hermes/<agent>/<channel>" (agent must pass validateAgentName).
std::string mqttTopic(const std::string& agent, MqttChannel channel);
/// Subscription pattern "hermes/+/<channel>" (every agent).
std::string mqttTopicAllAgents(MqttChannel channel);

struct ParsedTopic {
  std::string agent;
  MqttChannel channel = MqttChannel::kSubmap;
};
/// Parses "hermes/<agent>/<channel>"; errors name the topic.
Expected<ParsedTopic> parseMqttTopic(const std::string& topic);

enum class AckStatus : std::uint8_t { kAccepted = 0, kDuplicate = 1, kRejected = 2 };

struct AckMessage {
  AckStatus status = AckStatus::kAccepted;
  std::uint8_t reason_code = 0;  ///< hermes::ReceiveCode
  Uuid agent{};
  std::uint32_t session = 0;
  std::uint64_t seq = 0;
  std::uint32_t robot_id = 0;
  std::string reason;
  /// The robot may drop the submap from its spool (accepted or duplicate).
  bool acknowledges() const { return status != AckStatus::kRejected; }
};

struct HeartbeatMessage {
  Uuid agent{};
  std::uint32_t session = 0;
  std::uint64_t next_seq = 0;
  std::string name;
};

/// Encodes `ack`; a reason longer than kMaxAckReasonBytes is cut (with "...").
/// Errors: a status and reason_code that do not go together.
Expected<std::vector<std::uint8_t>> encodeAck(const AckMessage& ack);
Expected<AckMessage> decodeAck(const std::uint8_t* data, std::size_t size);

/// Errors: a name that fails validateAgentName.
Expected<std::vector<std::uint8_t>> encodeHeartbeat(const HeartbeatMessage& hb);
Expected<HeartbeatMessage> decodeHeartbeat(const std::uint8_t* data, std::size_t size);

}  // namespace hermes::transport
