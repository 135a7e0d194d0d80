#include "hermes/core/wire_format.h"
#include "hermes/transport/mqtt_links.h"

namespace hermes::transport {

static_assert(kAckReasonCodes == kReceiveCodes, "mqtt ack reason codes mirror hermes::ReceiveCode");

AckMessage ackFor(const ReceiveResult& r, const Uuid& agent) {
  AckMessage a;
  switch (r.verdict) {
    case ArrivalVerdict::kAccept: a.status = AckStatus::kAccepted; break;
    case ArrivalVerdict::kDuplicate:
    case ArrivalVerdict::kStale: a.status = AckStatus::kDuplicate; break;
    case ArrivalVerdict::kRejected: a.status = AckStatus::kRejected; break;
  }
  a.reason_code = static_cast<std::uint8_t>(r.code);
  a.agent = agent;
  a.session = r.routing.session;
  a.seq = r.routing.seq;
  a.robot_id = r.robot;
  a.reason = r.reason;
  return a;
}

Expected<std::unique_ptr<MqttServerLink>> MqttServerLink::create(const MqttParams& params) {
  auto client = MqttClient::create(params, params.client_id_prefix + "-server",
                                   {{mqttTopicAllAgents(MqttChannel::kSubmap), 2},
                                    {mqttTopicAllAgents(MqttChannel::kHeartbeat), 0}});
  if (!client) return Error{client.error()};
  return std::unique_ptr<MqttServerLink>(new MqttServerLink(std::move(*client)));
}

ServerLinkEvents MqttServerLink::poll() {
  ServerLinkEvents out;
  for (MqttEvent& e : client_->drain()) {
    if (e.kind == MqttEvent::Kind::kConnectionLost) {
      out.problems.push_back("connection to MQTT broker " + client_->broker() + " lost: " + e.text);
      continue;
    }
    if (e.kind != MqttEvent::Kind::kMessage) continue;
    auto topic = parseMqttTopic(e.topic);
    if (!topic) {
      out.problems.push_back("message dropped: " + topic.error());
      continue;
    }
    if (topic->channel == MqttChannel::kSubmap) {
      out.frames.push_back({topic->agent, std::move(e.payload)});
    } else if (topic->channel == MqttChannel::kHeartbeat) {
      auto hb = decodeHeartbeat(e.payload.data(), e.payload.size());
      if (!hb)
        out.problems.push_back("malformed heartbeat on " + e.topic + " dropped: " + hb.error());
      else if (hb->name != topic->agent)
        out.problems.push_back("heartbeat on " + e.topic + " names robot '" + hb->name + "': dropped");
      else
        out.heartbeats.push_back(std::move(*hb));
    } else {
      out.problems.push_back("unexpected message on " + e.topic + " dropped");
    }
  }
  return out;
}

ReceiveResult MqttServerLink::handle(const IncomingFrame& in, const Receive& receive) {
  // The topic names the robot; the frame's own session and seq are taken as
  // claimed (only its uuid is checked against the topic).
  const Uuid agent = agentUuid(in.agent);
  SubmapHeader claimed;
  claimed.agent = agent;
  const auto header = parseFrameHeader(in.frame.data(), in.frame.size());
  if (header) {
    claimed.session = header->routing.session;
    claimed.seq = header->routing.seq;
  }
  ReceiveResult r = receive(in.frame.data(), in.frame.size(), header ? &claimed : nullptr);
  if (!header || r.code == ReceiveCode::kMalformed) {  // the routing may be unreadable
    r.routing.session = header ? header->routing.session : 0;
    r.routing.seq = header ? header->routing.seq : 0;
  }
  if (r.code == ReceiveCode::kRoutingMismatch)
    r.reason = "frame of uuid " + hermes::toString(r.routing.agent) + " on the topic of robot '" + in.agent +
               "' (expected uuid " + hermes::toString(agent) + "): " + r.reason;
  if (!sendAck(in.agent, ackFor(r, agent))) ++unsent_acks_;
  return r;
}

Status MqttServerLink::sendAck(const std::string& agent, const AckMessage& ack) {
  auto payload = encodeAck(ack);
  if (!payload) return Error{payload.error()};
  return client_->publish(mqttTopic(agent, MqttChannel::kAck), *payload, 2);
}

Status MqttServerLink::sendGlobalPose(const std::string& agent, const GlobalPoseMessage& msg) {
  if (Status s = validateAgentName(agent); !s) return Error{"mqtt: " + s.error()};
  auto payload = encodeGlobalPose(msg);
  if (!payload) return Error{payload.error()};
  return client_->publish(mqttTopic(agent, MqttChannel::kGlobalPose), *payload, 0);
}

}  // namespace hermes::transport
