#include "hermes/transport/mqtt_links.h"

#include <optional>

namespace hermes::transport {
namespace {

/// The decoded message when it names this robot's uuid; else reported and counted.
template <class Message>
std::optional<Message> ours(Expected<Message> decoded, const MqttEvent& e, const char* what,
                            const Uuid& uuid, std::size_t* malformed, AgentLinkEvents* out) {
  if (!decoded) {
    ++*malformed;
    out->problems.push_back("malformed payload on " + e.topic + " dropped: " + decoded.error());
    return std::nullopt;
  }
  if (decoded->agent != uuid) {
    ++*malformed;
    out->problems.push_back(std::string(what) + " on " + e.topic + " is for uuid " +
                            hermes::toString(decoded->agent) + ", not this robot's " +
                            hermes::toString(uuid) + ": dropped");
    return std::nullopt;
  }
  return std::move(*decoded);
}

}  // namespace

Expected<std::unique_ptr<MqttAgentLink>> MqttAgentLink::create(const MqttParams& params,
                                                               const std::string& robot,
                                                               const Uuid& uuid) {
  if (Status s = validateAgentName(robot); !s) return Error{"mqtt: " + s.error()};
  auto client = MqttClient::create(params, params.client_id_prefix + "-agent-" + robot,
                                   {{mqttTopic(robot, MqttChannel::kAck), 2},
                                    {mqttTopic(robot, MqttChannel::kGlobalPose), 0}});
  if (!client) return Error{client.error()};
  return std::unique_ptr<MqttAgentLink>(new MqttAgentLink(robot, uuid, std::move(*client)));
}

Status MqttAgentLink::sendSubmap(const std::vector<std::uint8_t>& frame) {
  Status s = client_->publish(mqttTopic(robot_, MqttChannel::kSubmap), frame, 2);
  if (!s) refused_offline_ = true;
  return s;
}

Status MqttAgentLink::sendHeartbeat(std::uint32_t session, std::uint64_t next_seq) {
  HeartbeatMessage hb;
  hb.agent = uuid_;
  hb.session = session;
  hb.next_seq = next_seq;
  hb.name = robot_;
  auto payload = encodeHeartbeat(hb);
  if (!payload) return Error{payload.error()};
  return client_->publish(mqttTopic(robot_, MqttChannel::kHeartbeat), *payload, 0);
}

AgentLinkEvents MqttAgentLink::poll() {
  AgentLinkEvents out;
  for (MqttEvent& e : client_->drain()) {
    switch (e.kind) {
      case MqttEvent::Kind::kConnected:
        out.connected_now = true;
        // Refused publishes are cleared on every connection: whatever they
        // carried goes out again with everything else unacknowledged.
        if (refused_offline_.exchange(false) || !e.session_present) out.resend_all = true;
        break;
      case MqttEvent::Kind::kConnectionLost:
        out.problems.push_back("connection to MQTT broker " + client_->broker() + " lost: " + e.text);
        break;
      case MqttEvent::Kind::kMessage: {
        auto topic = parseMqttTopic(e.topic);
        if (topic && topic->channel == MqttChannel::kGlobalPose) {
          auto pose = ours(decodeGlobalPose(e.payload.data(), e.payload.size()), e, "global pose",
                           uuid_, &malformed_, &out);
          if (pose) out.global_poses.push_back(pose->update);
        } else if (auto ack = ours(decodeAck(e.payload.data(), e.payload.size()), e, "ack", uuid_,
                                   &malformed_, &out)) {
          out.acks.push_back(std::move(*ack));
        }
        break;
      }
    }
  }
  return out;
}

}  // namespace hermes::transport
