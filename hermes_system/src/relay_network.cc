#include "hermes/system/relay_network.h"

#include <algorithm>
#include <filesystem>
#include <limits>

namespace hermes::system {
namespace fs = std::filesystem;

Expected<std::unique_ptr<RelayNetwork>> RelayNetwork::create(
    Scenario scenario, const agent::RelayParams& relay, const agent::UplinkParams& uplink,
    const std::vector<std::string>& robots, const std::string& spool_root, std::uint64_t seed,
    std::size_t packet_bytes, NetworkHooks hooks) {
  if (Status s = relay.validate(); !s) return Error{s.error()};
  std::unique_ptr<RelayNetwork> net(new RelayNetwork());
  net->scenario_ = std::move(scenario);
  net->relay_ = relay;
  net->robots_ = robots;
  net->hooks_ = std::move(hooks);
  net->server_link_.assign(robots.size(), -1);
  net->spools_.resize(robots.size());
  net->own_evidence_.resize(robots.size());
  auto index = [&](const std::string& name) -> std::size_t {
    return static_cast<std::size_t>(std::find(robots.begin(), robots.end(), name) - robots.begin());
  };
  std::uint64_t link_seed = seed;
  for (const ScenarioLink& def : net->scenario_.links) {
    Link l;
    l.def = &def;
    l.from = index(def.from);
    int senders = 1;
    if (def.toServer()) {
      l.slots[l.from] = 0;
      if (relay.enabled)
        for (const ScenarioLink& other : net->scenario_.links)
          if (other.to == def.from) l.slots[index(other.from)] = senders++;
      net->server_link_[l.from] = static_cast<int>(net->links_.size());
    } else {
      l.to = index(def.to);
      l.slots[l.from] = 0;
    }
    l.link = std::make_unique<SharedLink>(def.trace, senders, link_seed++, packet_bytes);
    net->links_.push_back(std::move(l));
  }
  for (std::size_t r = 0; r < robots.size(); ++r) {
    const int sl = net->server_link_[r];
    if (sl < 0 || net->links_[sl].slots.size() < 2) continue;  // relays nobody
    const fs::path dir = fs::path(spool_root) / (robots[r] + ".relay");
    std::error_code ec;
    fs::remove_all(dir, ec);  // a run starts fresh, like the robots' own spools
    RelayNetwork* self = net.get();
    auto spool = agent::RelaySpool::open(
        dir.string(), uplink,
        [self, sl](const std::string& origin, std::uint32_t session, std::uint64_t seq,
                      const std::vector<std::uint8_t>& frame) {
          const std::size_t o = static_cast<std::size_t>(
              std::find(self->robots_.begin(), self->robots_.end(), origin) - self->robots_.begin());
          const auto slot = self->links_[sl].slots.find(o);
          if (slot == self->links_[sl].slots.end()) return;  // not one this relay serves
          self->queue(static_cast<std::size_t>(sl), slot->second, o, session, seq, frame, self->now_);
        });
    if (!spool) return Error{"relay " + robots[r] + ": " + spool.error()};
    net->spools_[r] = std::move(*spool);
  }
  for (const std::string& r : robots) {
    RobotTraffic t;
    t.robot = r;
    net->traffic_.push_back(t);
  }
  return net;
}

int RelayNetwork::route(std::size_t agent, double now) const {
  const int sl = server_link_[agent];
  if (sl >= 0 && links_[sl].link->trace().at(now).rate_mbitps > 0) return sl;
  int first_robot = -1;
  if (relay_.enabled)
    for (std::size_t i = 0; i < links_.size(); ++i) {
      const Link& l = links_[i];
      if (l.from != agent || l.def->toServer()) continue;
      if (l.link->trace().at(now).rate_mbitps > 0) return static_cast<int>(i);
      if (first_robot < 0) first_robot = static_cast<int>(i);
    }
  return sl >= 0 ? sl : first_robot;
}

int RelayNetwork::hopLink(std::size_t origin, std::size_t relay) const {
  for (std::size_t i = 0; i < links_.size(); ++i)
    if (links_[i].from == origin && !links_[i].def->toServer() && links_[i].to == relay)
      return static_cast<int>(i);
  return -1;
}

void RelayNetwork::queue(std::size_t link, int slot, std::size_t origin, std::uint32_t session,
                         std::uint64_t seq, const std::vector<std::uint8_t>& frame, double now) {
  LinkMessage m;
  m.sender = slot;
  m.id = next_message_++;
  m.bytes = frame.size();
  m.payload = std::make_shared<const std::vector<std::uint8_t>>(frame);
  messages_[m.id] = Message{link, origin, session, seq};
  links_[link].link->send(std::move(m), now);
}

void RelayNetwork::send(std::size_t agent, std::uint32_t session, std::uint64_t seq,
                        const std::vector<std::uint8_t>& frame, double now) {
  now_ = std::max(now_, now);
  const int l = route(agent, now);
  if (l < 0) return;  // no link at all: the spool resends it later
  if (spools_[agent])  // a relay's own stream: its credibility evidence
    own_evidence_[agent].onFrame(frame, now, !own_sent_.insert({agent, session, seq}).second);
  queue(static_cast<std::size_t>(l), 0, agent, session, seq, frame, now);
}

void RelayNetwork::onArrival(const Link& l, const Message& m, const LinkDelivery& d) {
  const std::size_t link = static_cast<std::size_t>(&l - links_.data());
  if (l.def->toServer()) {
    if (!hooks_.to_server(m.origin, m.session, m.seq, *d.message.payload, d.arrival_time)) return;
    const double ack = l.link->ackArrival(d.arrival_time);
    if (ack >= 0) acks_.push_back({ack, AckKind::kServerToSender, link, m.origin, m.session, m.seq});
    return;
  }
  // A hop: the relay spools the submap and tells the origin.
  agent::RelaySpool* spool = spools_[l.to].get();
  if (!spool) return;
  std::vector<std::uint8_t> frame = *d.message.payload;
  auto offer = spool->offer(robots_[m.origin], m.session, m.seq, std::move(frame), d.arrival_time);
  if (!offer) return;  // damaged or refused: not acknowledged, the origin resends
  if (*offer != agent::RelaySpool::Offer::kStored) ++traffic_[m.origin].hop_duplicates;
  const double ack = l.link->ackArrival(d.arrival_time);
  if (ack < 0) return;
  const AckKind kind = *offer == agent::RelaySpool::Offer::kAlreadyAcked ? AckKind::kRelayToOrigin
                                                                       : AckKind::kHop;
  acks_.push_back({ack, kind, link, m.origin, m.session, m.seq});
}

void RelayNetwork::deliver(double t) {
  now_ = std::max(now_, t);
  for (Link& l : links_)
    for (LinkDelivery& d : l.link->advanceTo(t)) {
      auto it = messages_.find(d.message.id);
      if (it == messages_.end()) continue;
      const Message m = it->second;
      messages_.erase(it);
      if (d.lost) {
        if (hooks_.lost) hooks_.lost(m.origin);
        continue;
      }
      onArrival(l, m, d);
    }
}

void RelayNetwork::acknowledge(double t) {
  std::stable_sort(acks_.begin(), acks_.end(),
                   [](const PendingAck& a, const PendingAck& b) { return a.time < b.time; });
  std::vector<PendingAck> later;
  std::size_t done = 0;
  for (; done < acks_.size() && acks_[done].time <= t; ++done) {
    const PendingAck k = acks_[done];
    const std::size_t sender = links_[k.link].from;
    switch (k.kind) {
      case AckKind::kHop:
        hooks_.handed_over(k.origin, k.session, k.seq, t);
        break;
      case AckKind::kServerToSender:
        if (sender == k.origin) {
          hooks_.acked(k.origin, k.session, k.seq, t);
          break;
        }
        if (spools_[sender] && spools_[sender]->onServerAck(robots_[k.origin], k.session, k.seq, t)) {
          ++traffic_[k.origin].relayed_submaps;
          std::string& by = traffic_[k.origin].relayed_by;
          if (("," + by + ",").find("," + robots_[sender] + ",") == std::string::npos)
            by += (by.empty() ? "" : ",") + robots_[sender];
        }
        // On to the origin over its link to this relay; kept while that link drops it.
        if (const int hop = hopLink(k.origin, sender); hop >= 0) {
          const double back = links_[hop].link->ackArrival(t);
          if (back >= 0)
            later.push_back({back, AckKind::kRelayToOrigin, static_cast<std::size_t>(hop), k.origin,
                             k.session, k.seq});
          else
            later.push_back({t + relay_.ack_retry_s, AckKind::kServerToSender, k.link, k.origin,
                             k.session, k.seq});
        }
        break;
      case AckKind::kRelayToOrigin:
        hooks_.acked(k.origin, k.session, k.seq, t);
        break;
    }
  }
  acks_.erase(acks_.begin(), acks_.begin() + static_cast<std::ptrdiff_t>(done));
  acks_.insert(acks_.end(), later.begin(), later.end());
}

void RelayNetwork::resplit(std::size_t relay, double t) {
  Link& l = links_[server_link_[relay]];
  std::vector<agent::RelayStream> streams;
  std::vector<int> slots;
  for (const auto& [origin, slot] : l.slots) {
    streams.push_back(origin == relay ? own_evidence_[relay].stream(t, true)
                                      : spools_[relay]->stream(robots_[origin], t));
    slots.push_back(slot);
  }
  const std::vector<agent::StreamShare> shares = agent::splitUplink(relay_, streams);
  for (std::size_t i = 0; i < shares.size(); ++i)
    l.link->setShare(slots[i], shares[i].weight, shares[i].guaranteed_Bps);
}

void RelayNetwork::poll(double t, double period_s) {
  now_ = std::max(now_, t);
  const bool split = t + 1e-9 >= next_split_;
  for (std::size_t r = 0; r < spools_.size(); ++r) {
    if (!spools_[r]) continue;
    if (split) resplit(r, t);
    spools_[r]->poll(t);
  }
  if (split) next_split_ = t + period_s;
}

void RelayNetwork::onServerBack() {
  for (auto& s : spools_)
    if (s) s->onReconnect();
}

std::size_t RelayNetwork::pendingWork() const {
  std::size_t n = acks_.size();
  for (const auto& s : spools_)
    if (s) n += s->pendingBytes();
  return n;
}

void RelayNetwork::sample(double t, double period_s) {
  for (std::size_t i = 0; i < links_.size(); ++i) {
    const Link& l = links_[i];
    if (!l.def->toServer()) continue;
    for (const auto& [origin, slot] : l.slots) {
      if (origin == l.from) continue;
      const double served = l.link->servedBytes(slot);
      const double busy = l.link->backloggedUpSeconds(slot);
      auto& last = last_served_[{i, slot}];
      RelayedSample s;
      s.time_s = t - period_s;
      s.relay = robots_[l.from];
      s.origin = robots_[origin];
      s.served_kB = (served - last.first) / 1000.0;
      s.backlogged_up_s = busy - last.second;
      last = {served, busy};
      samples_.push_back(s);
    }
  }
}

std::optional<double> RelayNetwork::minRelayedMbitps(double period_s, const std::string& origin) const {
  std::optional<double> lowest;
  for (const RelayedSample& s : samples_) {
    if (s.backlogged_up_s < 0.5 * period_s || (!origin.empty() && s.origin != origin)) continue;
    const double mbitps = s.served_kB * 8e-3 / s.backlogged_up_s;
    if (!lowest || mbitps < *lowest) lowest = mbitps;
  }
  return lowest;
}

double RelayNetwork::ownBytes(std::size_t agent) const {
  double b = 0;
  for (const Link& l : links_)
    if (l.from == agent) b += l.link->servedBytes(0);
  return b;
}

std::optional<double> RelayNetwork::serverCapacityKBps(std::size_t agent, double t) const {
  const int sl = server_link_[agent];
  if (sl < 0) return std::nullopt;
  return links_[sl].link->trace().at(t).rate_mbitps * 125.0;
}

std::vector<RobotTraffic> RelayNetwork::traffic() const {
  std::vector<RobotTraffic> out = traffic_;
  for (std::size_t r = 0; r < out.size(); ++r) {
    out[r].own_bytes = ownBytes(r);
    const int sl = server_link_[r];
    if (sl < 0) continue;
    for (const auto& [origin, slot] : links_[sl].slots)
      if (origin != r) out[r].relayed_bytes += links_[sl].link->servedBytes(slot);
  }
  return out;
}

const agent::RelaySpool* RelayNetwork::spool(std::size_t agent) const {
  return agent < spools_.size() ? spools_[agent].get() : nullptr;
}

}  // namespace hermes::system
