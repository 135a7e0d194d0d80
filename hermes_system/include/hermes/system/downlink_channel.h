// The server's downlink in the offline runner (server/downlink.h): the packets
// it plans for the placed robots cross an emulated link of their own (the
// uplink's trace, its own loss draws: the uplink's results do not change with
// it), reach the robots' pipelines (AgentPipeline::onMapDown), and their
// acknowledgements come back over the same link (lost like any message). A
// server restart starts a new epoch: what was in flight is forgotten by the
// server and planned again; the robots keep what they took.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <vector>

#include "hermes/core/emulated_link.h"
#include "hermes/core/map_down.h"
#include "hermes/server/downlink.h"

namespace hermes::system {

class DownlinkChannel {
 public:
  DownlinkChannel(const server::DownlinkParams& params, const LinkTrace& trace, int agents,
                  std::uint64_t seed, std::size_t packet_bytes);

  /// A (re)created server: planning starts again under `epoch`.
  void newEpoch(std::uint64_t epoch);
  /// Plans at `t` for `recipients` (recipient i is agent agent_of[i]) and
  /// puts the packets on the link.
  void send(const server::GlobalMap& map, const std::vector<server::DownlinkRecipient>& recipients,
            const std::vector<std::size_t>& agent_of, double t);
  /// What reached the robots by `t` goes to `deliver(agent, bytes)`, whose
  /// acknowledgement (nullopt: none) travels back; acknowledgements due by
  /// `t` reach the server's downlink (with `server_up`; else they are lost).
  void advance(double t, bool server_up,
               const std::function<std::optional<MapDownAck>(std::size_t, const std::vector<std::uint8_t>&)>&
                   deliver);

  /// Bytes put on the link for each agent (resends included) [B].
  std::uint64_t bytesTo(std::size_t agent) const { return agent < bytes_.size() ? bytes_[agent] : 0; }
  const server::Downlink& downlink() const { return *downlink_; }

 private:
  struct PendingAck {
    double time;
    MapDownAck ack;
  };
  server::DownlinkParams params_;
  std::unique_ptr<server::Downlink> downlink_;
  SharedLink link_;
  std::vector<std::uint64_t> bytes_;
  std::vector<PendingAck> acks_;  ///< in arrival order
  std::uint64_t next_id_ = 0;
};

}  // namespace hermes::system
