#include "hermes/transport/mqtt_links.h"

namespace hermes::transport {

Expected<std::unique_ptr<MqttAgentLink>> MqttAgentLink::create(const MqttParams& params,
                                                               const std::string& robot,
                                                               const Uuid& uuid) {
  if (Status s = validateAgentName(robot); !s) return Error{"mqtt: " + s.error()};
  auto client = MqttClient::create(params, params.client_id_prefix + "-agent-" + robot,
                                   {{mqttTopic(robot, MqttChannel::kAck), 2}});
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
        auto ack = decodeAck(e.payload.data(), e.payload.size());
        if (!ack) {
          ++malformed_;
          out.problems.push_back("malformed payload on " + e.topic + " dropped: " + ack.error());
        } else if (ack->agent != uuid_) {
          ++malformed_;
          out.problems.push_back("ack on " + e.topic + " is for uuid " + hermes::toString(ack->agent) +
                                 ", not this robot's " + hermes::toString(uuid_) + ": dropped");
        } else {
          out.acks.push_back(std::move(*ack));
        }
        break;
      }
    }
  }
  return out;
}

}  // namespace hermes::transport
