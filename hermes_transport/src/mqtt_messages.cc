#include "hermes/transport/mqtt_messages.h"

#include <cstring>

#include "le_bytes.h"

namespace hermes::transport {
namespace {

constexpr char kTopicRoot[] = "hermes";
constexpr std::uint8_t kAckVersion = 1, kHeartbeatVersion = 1;
constexpr std::size_t kAckFixedBytes = 42, kHeartbeatFixedBytes = 38;

using le::get;
using le::put;

void putUuid(std::vector<std::uint8_t>* out, const Uuid& id) { out->insert(out->end(), id.begin(), id.end()); }

Uuid getUuid(const std::uint8_t* p) {
  Uuid id;
  std::memcpy(id.data(), p, id.size());
  return id;
}

/// The common checks of a fixed-size header followed by `n` text bytes at
/// `len_at`; empty when the sizes agree, else the error text.
std::string checkSizes(const char* what, const std::uint8_t* data, std::size_t size,
                       std::size_t fixed, std::size_t len_at, const char* magic,
                       std::uint8_t version, std::size_t* text_bytes) {
  const std::string prefix = std::string("mqtt ") + what + ": ";
  if (!data && size > 0) return prefix + "no data";
  if (size < fixed)
    return prefix + "payload of " + std::to_string(size) + " bytes is shorter than the " +
           std::to_string(fixed) + "-byte fixed part";
  if (std::memcmp(data, magic, 4) != 0) return prefix + "bad magic at offset 0 (expected \"" + magic + "\")";
  if (data[4] != version)
    return prefix + "unsupported version " + std::to_string(data[4]) + " at offset 4 (this build reads " +
           std::to_string(version) + ")";
  *text_bytes = static_cast<std::size_t>(get(data + len_at, 2));
  if (size != fixed + *text_bytes)
    return prefix + "length field at offset " + std::to_string(len_at) + " says " +
           std::to_string(*text_bytes) + " text bytes, the payload has " +
           std::to_string(size - fixed);
  return {};
}

bool statusMatchesCode(AckStatus status, std::uint8_t code) {
  switch (status) {
    case AckStatus::kAccepted: return code == 0;
    case AckStatus::kDuplicate: return code == 1 || code == 2;
    case AckStatus::kRejected: return code >= 3 && code < kAckReasonCodes;
  }
  return false;
}

}  // namespace

const char* toString(MqttChannel channel) {
  switch (channel) {
    case MqttChannel::kSubmap: return "submap";
    case MqttChannel::kAck: return "ack";
    case MqttChannel::kHeartbeat: return "heartbeat";
    case MqttChannel::kGlobalPose: return "global_pose";
  }
  return "?";
}

Status validateAgentName(const std::string& name) {
  if (name.empty() || name.size() > kMaxAgentNameBytes)
    return Error{"robot name '" + name + "' must have 1.." + std::to_string(kMaxAgentNameBytes) +
                 " characters to be an MQTT topic level"};
  for (char ch : name) {
    const bool ok = (ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z') || (ch >= '0' && ch <= '9') ||
                    ch == '_' || ch == '-' || ch == '.';
    if (!ok)
      return Error{"robot name '" + name + "' holds '" + std::string(1, ch) +
                   "': only letters, digits, '_', '-' and '.' can make an MQTT topic level"};
  }
  return Status::Ok();
}

std::string mqttTopic(const std::string& agent, MqttChannel channel) {
  return std::string(kTopicRoot) + "/" + agent + "/" + toString(channel);
}

std::string mqttTopicAllAgents(MqttChannel channel) {
  return std::string(kTopicRoot) + "/+/" + toString(channel);
}

Expected<ParsedTopic> parseMqttTopic(const std::string& topic) {
  const std::string root = std::string(kTopicRoot) + "/";
  const auto last = topic.rfind('/');
  if (topic.compare(0, root.size(), root) != 0 || last == std::string::npos || last < root.size())
    return Error{"topic '" + topic + "' is not hermes/<agent>/<channel>"};
  ParsedTopic t;
  t.agent = topic.substr(root.size(), last - root.size());
  if (Status s = validateAgentName(t.agent); !s) return Error{"topic '" + topic + "': " + s.error()};
  const std::string channel = topic.substr(last + 1);
  if (channel == "submap") t.channel = MqttChannel::kSubmap;
  else if (channel == "ack") t.channel = MqttChannel::kAck;
  else if (channel == "heartbeat") t.channel = MqttChannel::kHeartbeat;
  else if (channel == "global_pose") t.channel = MqttChannel::kGlobalPose;
  else return Error{"topic '" + topic + "': unknown channel '" + channel + "'"};
  return t;
}

Expected<std::vector<std::uint8_t>> encodeAck(const AckMessage& ack) {
  if (!statusMatchesCode(ack.status, ack.reason_code))
    return Error{"mqtt ack: status " + std::to_string(static_cast<int>(ack.status)) +
                 " does not go with reason code " + std::to_string(ack.reason_code)};
  std::string reason = ack.reason;
  if (reason.size() > kMaxAckReasonBytes) reason = reason.substr(0, kMaxAckReasonBytes - 3) + "...";
  std::vector<std::uint8_t> out;
  out.reserve(kAckFixedBytes + reason.size());
  out.insert(out.end(), {'H', 'A', 'C', 'K', kAckVersion});
  put(&out, static_cast<std::uint8_t>(ack.status), 1);
  put(&out, ack.reason_code, 1);
  put(&out, 0, 1);
  putUuid(&out, ack.agent);
  put(&out, ack.session, 4);
  put(&out, ack.seq, 8);
  put(&out, ack.robot_id, 4);
  put(&out, reason.size(), 2);
  out.insert(out.end(), reason.begin(), reason.end());
  return out;
}

Expected<AckMessage> decodeAck(const std::uint8_t* data, std::size_t size) {
  std::size_t n = 0;
  if (std::string e = checkSizes("ack", data, size, kAckFixedBytes, 40, "HACK", kAckVersion, &n); !e.empty())
    return Error{e};
  if (n > kMaxAckReasonBytes)
    return Error{"mqtt ack: reason of " + std::to_string(n) + " bytes at offset 42 exceeds " +
                 std::to_string(kMaxAckReasonBytes)};
  if (data[5] > 2) return Error{"mqtt ack: unknown status " + std::to_string(data[5]) + " at offset 5"};
  if (data[7] != 0) return Error{"mqtt ack: reserved byte at offset 7 is not 0"};
  AckMessage a;
  a.status = static_cast<AckStatus>(data[5]);
  a.reason_code = data[6];
  if (!statusMatchesCode(a.status, a.reason_code))
    return Error{"mqtt ack: reason code " + std::to_string(a.reason_code) +
                 " at offset 6 does not go with status " + std::to_string(data[5])};
  a.agent = getUuid(data + 8);
  a.session = static_cast<std::uint32_t>(get(data + 24, 4));
  a.seq = get(data + 28, 8);
  a.robot_id = static_cast<std::uint32_t>(get(data + 36, 4));
  a.reason.assign(reinterpret_cast<const char*>(data + kAckFixedBytes), n);
  return a;
}

Expected<std::vector<std::uint8_t>> encodeHeartbeat(const HeartbeatMessage& hb) {
  if (Status s = validateAgentName(hb.name); !s) return Error{"mqtt heartbeat: " + s.error()};
  std::vector<std::uint8_t> out;
  out.reserve(kHeartbeatFixedBytes + hb.name.size());
  out.insert(out.end(), {'H', 'H', 'B', 'T', kHeartbeatVersion, 0, 0, 0});
  putUuid(&out, hb.agent);
  put(&out, hb.session, 4);
  put(&out, hb.next_seq, 8);
  put(&out, hb.name.size(), 2);
  out.insert(out.end(), hb.name.begin(), hb.name.end());
  return out;
}

Expected<HeartbeatMessage> decodeHeartbeat(const std::uint8_t* data, std::size_t size) {
  std::size_t n = 0;
  if (std::string e = checkSizes("heartbeat", data, size, kHeartbeatFixedBytes, 36, "HHBT",
                                 kHeartbeatVersion, &n);
      !e.empty())
    return Error{e};
  if (data[5] != 0 || data[6] != 0 || data[7] != 0)
    return Error{"mqtt heartbeat: reserved bytes at offsets 5..7 are not 0"};
  HeartbeatMessage hb;
  hb.agent = getUuid(data + 8);
  hb.session = static_cast<std::uint32_t>(get(data + 24, 4));
  hb.next_seq = get(data + 28, 8);
  hb.name.assign(reinterpret_cast<const char*>(data + kHeartbeatFixedBytes), n);
  if (Status s = validateAgentName(hb.name); !s)
    return Error{"mqtt heartbeat: name at offset 38: " + s.error()};
  return hb;
}

}  // namespace hermes::transport
