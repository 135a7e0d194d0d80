#include "hermes/system/downlink_channel.h"

#include <algorithm>

namespace hermes::system {

DownlinkChannel::DownlinkChannel(const server::DownlinkParams& params, const LinkTrace& trace,
                                 int agents, std::uint64_t seed, std::size_t packet_bytes)
    : params_(params),
      downlink_(std::make_unique<server::Downlink>(params, 1)),
      link_(trace, agents, seed, packet_bytes),
      bytes_(static_cast<std::size_t>(agents), 0) {}

void DownlinkChannel::newEpoch(std::uint64_t epoch) {
  downlink_ = std::make_unique<server::Downlink>(params_, epoch);
  acks_.clear();  // for the old epoch: the new downlink ignores them anyway
}

void DownlinkChannel::send(const server::GlobalMap& map,
                           const std::vector<server::DownlinkRecipient>& recipients,
                           const std::vector<std::size_t>& agent_of, double t) {
  for (const server::Downlink::Outgoing& o : downlink_->plan(map, recipients, t)) {
    std::size_t agent = bytes_.size();
    for (std::size_t i = 0; i < recipients.size(); ++i)
      if (recipients[i].robot == o.robot) agent = agent_of[i];
    if (agent >= bytes_.size()) continue;
    LinkMessage m;
    m.sender = static_cast<int>(agent);
    m.id = next_id_++;
    m.bytes = o.bytes->size();
    m.payload = o.bytes;
    link_.send(std::move(m), t);
    bytes_[agent] += o.bytes->size();
  }
}

void DownlinkChannel::advance(
    double t, bool server_up,
    const std::function<std::optional<MapDownAck>(std::size_t, const std::vector<std::uint8_t>&)>& deliver) {
  for (const LinkDelivery& d : link_.advanceTo(t)) {
    if (d.lost || !d.message.payload) continue;
    const std::optional<MapDownAck> ack =
        deliver(static_cast<std::size_t>(d.message.sender), *d.message.payload);
    if (!ack) continue;
    const double arrival = link_.ackArrival(d.arrival_time);
    if (arrival >= 0) acks_.push_back({arrival, *ack});
  }
  std::stable_sort(acks_.begin(), acks_.end(),
                   [](const PendingAck& a, const PendingAck& b) { return a.time < b.time; });
  std::size_t done = 0;
  for (; done < acks_.size() && acks_[done].time <= t; ++done)
    if (server_up) downlink_->onAck(acks_[done].ack, acks_[done].time);
  acks_.erase(acks_.begin(), acks_.begin() + static_cast<std::ptrdiff_t>(done));
}

}  // namespace hermes::system
