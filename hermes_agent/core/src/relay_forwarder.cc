#include "hermes/agent/relay_forwarder.h"

#include <algorithm>
#include <cmath>

#include "hermes/core/wire_format.h"

namespace hermes::agent {

Expected<std::vector<std::string>> parseRobotList(const std::string& list) {
  std::vector<std::string> out;
  std::size_t start = 0;
  const auto trim = [](std::string s) {
    const auto b = s.find_first_not_of(" \t");
    const auto e = s.find_last_not_of(" \t");
    return b == std::string::npos ? std::string() : s.substr(b, e - b + 1);
  };
  if (trim(list).empty()) return out;
  while (start <= list.size()) {
    const auto comma = list.find(',', start);
    const std::string name = trim(list.substr(start, comma == std::string::npos ? std::string::npos
                                                                                : comma - start));
    if (Status s = checkRobotName(name); !s) return Error{"robot list '" + list + "': " + s.error()};
    if (std::find(out.begin(), out.end(), name) != out.end())
      return Error{"robot list '" + list + "': " + name + " named twice"};
    out.push_back(name);
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return out;
}

Expected<std::unique_ptr<RelayForwarder>> RelayForwarder::open(
    const std::string& dir, const std::vector<std::string>& origins, const RelayParams& relay,
    const UplinkParams& uplink, double split_period_s, Send send) {
  if (Status s = relay.validate(); !s) return Error{s.error()};
  if (!(split_period_s > 0)) return Error{"relay forwarder: split period must be > 0 s"};
  std::unique_ptr<RelayForwarder> f(new RelayForwarder(relay, split_period_s, std::move(send)));
  for (const std::string& o : origins) {
    if (Status s = checkRobotName(o); !s) return Error{"relay forwarder: " + s.error()};
    f->served_.insert(o);
    f->buckets_[o];
    f->uuid_to_origin_[toString(agentUuid(o))] = o;
  }
  RelayForwarder* self = f.get();
  // The spool's senders hand their frames to the buckets (under mu_: the spool
  // is only called from the forwarder's own methods).
  auto spool = RelaySpool::open(
      dir, uplink,
      [self](const std::string& origin, std::uint32_t session, std::uint64_t seq,
             const std::vector<std::uint8_t>& frame) {
        Bucket& b = self->buckets_[origin];  // a folder of an earlier run's origin goes on too
        self->uuid_to_origin_.emplace(toString(agentUuid(origin)), origin);
        if (!b.keys.insert({session, seq}).second) return;  // a resend of one still waiting
        b.queue.push_back(Waiting{session, seq, frame});
      });
  if (!spool) return Error{spool.error()};
  f->spool_ = std::move(*spool);
  for (const std::string& o : f->spool_->origins()) {
    f->buckets_[o];
    f->uuid_to_origin_.emplace(toString(agentUuid(o)), o);
  }
  return f;
}

Expected<RelaySpool::Offer> RelayForwarder::offer(const std::string& origin, std::uint32_t session,
                                                  std::uint64_t seq, std::vector<std::uint8_t> frame,
                                                  double now) {
  std::lock_guard<std::mutex> lock(mu_);
  if (!served_.count(origin))
    return Error{"relay: not a relay for " + origin};
  auto header = peekFrame(frame.data(), frame.size());
  if (header && header->routing.agent != agentUuid(origin))
    return Error{"relay: a submap offered as " + origin + "'s belongs to agent " +
                 toString(header->routing.agent)};
  return spool_->offer(origin, session, seq, std::move(frame), now);  // damaged frames: its error
}

bool RelayForwarder::onServerAck(const std::string& origin, std::uint32_t session,
                                 std::uint64_t seq, double now) {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = buckets_.find(origin);
  if (it != buckets_.end() && it->second.keys.erase({session, seq})) {
    auto& q = it->second.queue;
    q.erase(std::remove_if(q.begin(), q.end(),
                           [&](const Waiting& w) { return w.session == session && w.seq == seq; }),
            q.end());
  }
  return spool_->onServerAck(origin, session, seq, now);
}

void RelayForwarder::onOwnFrame(std::uint32_t session, std::uint64_t seq,
                                const std::vector<std::uint8_t>& frame, double now) {
  std::lock_guard<std::mutex> lock(mu_);
  own_.onFrame(frame, now, !own_sent_.insert({session, seq}).second);
}

void RelayForwarder::resplit(double now, double uplink_Bps) {
  std::vector<RelayStream> streams{own_.stream(now, true)};
  std::vector<Bucket*> order;
  for (auto& [name, b] : buckets_) {
    streams.push_back(spool_->stream(name, now));
    order.push_back(&b);
  }
  const std::vector<StreamShare> shares = splitUplink(relay_, streams);
  double guaranteed = 0;
  std::size_t i = 1;
  for (const auto& [name, b] : buckets_) {
    if (spool_->pendingBytes(name) > 0) guaranteed += shares[i].guaranteed_Bps;
    ++i;
  }
  const double beyond = std::max(0.0, (std::isfinite(uplink_Bps) ? uplink_Bps : 0.0) - guaranteed);
  for (std::size_t k = 0; k < order.size(); ++k) {
    order[k]->weight = shares[k + 1].weight;
    order[k]->rate = shares[k + 1].guaranteed_Bps + shares[k + 1].weight * beyond;
  }
}

void RelayForwarder::poll(double now, double uplink_Bps) {
  std::lock_guard<std::mutex> lock(mu_);
  if (now >= next_split_) {
    resplit(now, uplink_Bps);
    next_split_ = now + split_period_s_;
  }
  spool_->poll(now);
  for (auto& [name, b] : buckets_) {
    if (b.last_t >= 0) b.tokens = std::min(b.tokens + b.rate * (now - b.last_t), b.rate * 1.0);
    b.last_t = now;
    while (!b.queue.empty() && b.tokens >= 0 && b.rate > 0) {
      Waiting w = std::move(b.queue.front());
      b.queue.pop_front();
      b.keys.erase({w.session, w.seq});
      b.tokens -= static_cast<double>(w.frame.size());
      b.forwarded_bytes += static_cast<double>(w.frame.size());
      ++b.forwarded;
      send_(name, w.session, w.seq, w.frame);
    }
  }
}

void RelayForwarder::onReconnect() {
  std::lock_guard<std::mutex> lock(mu_);
  spool_->onReconnect();
}

std::vector<std::string> RelayForwarder::origins() const {
  std::lock_guard<std::mutex> lock(mu_);
  std::vector<std::string> out;
  for (const auto& [name, b] : buckets_) out.push_back(name);
  return out;
}

std::string RelayForwarder::originOfUuid(const std::string& uuid) const {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = uuid_to_origin_.find(uuid);
  return it == uuid_to_origin_.end() ? std::string() : it->second;
}

std::vector<RelayForwarder::OriginState> RelayForwarder::states() const {
  std::lock_guard<std::mutex> lock(mu_);
  std::vector<OriginState> out;
  for (const auto& [name, b] : buckets_) {
    OriginState s;
    s.origin = name;
    if (const RelaySpool::OriginStats* st = spool_->stats(name)) s.stats = *st;
    s.pending = spool_->pendingCount(name);
    s.pending_bytes = spool_->pendingBytes(name);
    s.waiting = b.queue.size();
    s.rate_Bps = b.rate;
    s.weight = b.weight;
    s.forwarded_bytes = b.forwarded_bytes;
    s.forwarded = b.forwarded;
    out.push_back(s);
  }
  return out;
}

}  // namespace hermes::agent
