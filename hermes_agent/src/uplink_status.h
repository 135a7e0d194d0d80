// The Agent nodelet's uplink_status (std_msgs/String JSON, latched; after every
// new submap and at 1 Hz): session, submaps created by this process and
// replayed, windows, spool pending keys / bytes and cap -- what the delivery
// tests count as "sent" --, sends / resends / acks, worker-thread counters,
// per-stage timings [ms], the transport (MQTT client counters), relaying, and
// the nodelet's image counters (`frames`).
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "hermes/agent/agent_pipeline.h"
#include "hermes/transport/mqtt_links.h"
#include "ros_relay.h"

namespace hermes_agent {

/// What the nodelet itself knows beside its pipeline.
struct UplinkStatusContext {
  using Keys = std::vector<std::pair<std::uint32_t, std::uint64_t>>;  ///< (session, seq)
  std::string robot, uuid;
  const Keys* created = nullptr;   ///< submaps this process handed to the uplink
  const Keys* replayed = nullptr;
  std::int64_t spool_cap_bytes = 0;
  bool done = false;               ///< the sequence ended (done topic)
  std::string relay_via;           ///< this robot's relay, if any
  std::size_t hop_acks = 0;        ///< the relay's hop acknowledgements
  const RosRelay* relay = nullptr;  ///< set when this robot relays others
  hermes::transport::MqttAgentLink* mqtt = nullptr;  ///< set with transport mqtt
  nlohmann::json frames;           ///< image counters
};

nlohmann::json uplinkStatusJson(const hermes::agent::AgentPipeline& pipeline, const UplinkStatusContext& c);

}  // namespace hermes_agent
