#include "hermes/core/emulated_link.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace hermes {

SharedLink::SharedLink(LinkTrace trace, int senders, std::uint64_t seed, std::size_t packet_bytes)
    : trace_(std::move(trace)),
      queues_(static_cast<std::size_t>(senders)),
      transmitted_(static_cast<std::size_t>(senders), 0),
      served_(static_cast<std::size_t>(senders), 0.0),
      backlogged_up_s_(static_cast<std::size_t>(senders), 0.0),
      shares_(static_cast<std::size_t>(senders)),
      packet_bytes_(std::max<std::size_t>(packet_bytes, 64)),
      rng_(seed) {
  HERMES_CHECK(senders > 0, "a link needs at least one sender");
}

bool SharedLink::draw(double p) {
  if (p <= 0) return false;
  // 53-bit uniform in [0,1), identical on every platform for a seed.
  const double u = static_cast<double>(rng_() >> 11) * (1.0 / 9007199254740992.0);
  return u < p;
}

void SharedLink::send(LinkMessage msg, double now) {
  HERMES_CHECK(msg.sender >= 0 && msg.sender < static_cast<int>(queues_.size()),
               "unknown sender");
  if (now > now_) simulateTo(now);  // deliveries stay pending for advanceTo()
  msg.send_time = std::max(now, now_);
  const std::size_t bytes = std::max<std::size_t>(msg.bytes, 1);
  if (use_shares_ && queues_[msg.sender].empty()) {
    // Back from idle: join at the busy senders' virtual time.
    double v = std::numeric_limits<double>::infinity();
    for (std::size_t i = 0; i < queues_.size(); ++i)
      if (!queues_[i].empty()) v = std::min(v, shares_[i].vtime);
    if (std::isfinite(v)) shares_[msg.sender].vtime = std::max(shares_[msg.sender].vtime, v);
  }
  queues_[msg.sender].push_back({std::move(msg), bytes});
}

double SharedLink::ackArrival(double now) {
  const LinkState s = trace_.at(now);
  if (s.rate_mbitps <= 0 || draw(s.loss)) return -1.0;
  return now + s.latency_ms * 1e-3;
}

void SharedLink::setShare(int sender, double weight, double guaranteed_Bps) {
  HERMES_CHECK(sender >= 0 && sender < static_cast<int>(shares_.size()), "unknown sender");
  HERMES_CHECK(weight > 0 && std::isfinite(weight), "a share's weight must be > 0");
  HERMES_CHECK(guaranteed_Bps >= 0 && std::isfinite(guaranteed_Bps),
               "a share's guaranteed rate must be >= 0");
  Share& s = shares_[sender];
  if (!use_shares_)
    for (Share& o : shares_) o.refilled_at = now_;
  use_shares_ = true;
  s.weight = weight;
  s.guaranteed_Bps = guaranteed_Bps;
}

int SharedLink::pickSender() {
  if (use_shares_) return pickByShares();
  for (std::size_t k = 0; k < queues_.size(); ++k) {
    const int cand = (rr_next_ + static_cast<int>(k)) % static_cast<int>(queues_.size());
    if (!queues_[cand].empty()) {
      rr_next_ = (cand + 1) % static_cast<int>(queues_.size());
      return cand;
    }
  }
  return -1;
}

int SharedLink::pickByShares() {
  // Guarantees first (token buckets), then weighted fair queueing by virtual
  // time; a sender that was idle starts from the busy senders' virtual time
  // (no credit hoarded while it had nothing to send).
  const double depth = 2.0 * static_cast<double>(packet_bytes_);
  double min_busy_vtime = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < queues_.size(); ++i) {
    Share& s = shares_[i];
    s.tokens = std::min(depth, s.tokens + s.guaranteed_Bps * (now_ - s.refilled_at));
    s.refilled_at = now_;
    if (!queues_[i].empty()) min_busy_vtime = std::min(min_busy_vtime, s.vtime);
  }
  int by_guarantee = -1, by_weight = -1;
  for (std::size_t i = 0; i < queues_.size(); ++i) {
    if (queues_[i].empty()) continue;
    const Share& s = shares_[i];
    const double packet =
        static_cast<double>(std::min(packet_bytes_, queues_[i].front().remaining));
    if (s.guaranteed_Bps > 0 && s.tokens >= packet &&
        (by_guarantee < 0 || s.tokens > shares_[by_guarantee].tokens))
      by_guarantee = static_cast<int>(i);
    if (by_weight < 0 || s.vtime < shares_[by_weight].vtime) by_weight = static_cast<int>(i);
  }
  current_guaranteed_ = by_guarantee >= 0;
  return current_guaranteed_ ? by_guarantee : by_weight;
}

std::size_t SharedLink::queuedBytes(int sender) const {
  std::size_t n = 0;
  for (const auto& m : queues_[sender]) n += m.remaining;
  return n;
}

void SharedLink::completeMessage(int sender, double t) {
  InFlight done = std::move(queues_[sender].front());
  queues_[sender].pop_front();
  const LinkState s = trace_.at(t);
  LinkDelivery d;
  d.lost = draw(s.loss);
  d.arrival_time = t + s.latency_ms * 1e-3;
  transmitted_[sender] += done.msg.bytes;
  d.message = std::move(done.msg);
  pending_.push_back(std::move(d));
}

std::vector<LinkDelivery> SharedLink::advanceTo(double t) {
  simulateTo(t);
  std::vector<LinkDelivery> out;
  std::stable_sort(pending_.begin(), pending_.end(),
                   [](const LinkDelivery& a, const LinkDelivery& b) {
                     return a.arrival_time < b.arrival_time;
                   });
  auto it = pending_.begin();
  while (it != pending_.end() && it->arrival_time <= t) ++it;
  out.assign(std::make_move_iterator(pending_.begin()), std::make_move_iterator(it));
  pending_.erase(pending_.begin(), it);
  return out;
}

void SharedLink::simulateTo(double t) {
  while (now_ < t) {
    const LinkState s = trace_.at(now_);
    const double seg_end = std::min(t, trace_.nextChange(now_));
    const double bytes_per_s = s.rate_mbitps * 1e6 / 8.0;
    if (bytes_per_s <= 0) {  // outage: nothing moves
      now_ = seg_end;
      continue;
    }
    // Pick the packet to serve (round robin, or by shares).
    if (current_ < 0 || packet_left_ == 0) {
      current_ = pickSender();
      if (current_ < 0) {  // idle
        now_ = seg_end;
        continue;
      }
      packet_left_ = std::min(packet_bytes_, queues_[current_].front().remaining);
      if (use_shares_) {
        Share& sh = shares_[current_];
        const double packet = static_cast<double>(packet_left_);
        if (current_guaranteed_)
          sh.tokens -= packet;
        else
          sh.vtime += packet / sh.weight;
      }
    }
    const double need = static_cast<double>(packet_left_) / bytes_per_s;
    const double t0 = now_;
    const int serving = current_;
    std::size_t used = 0;
    if (now_ + need <= seg_end) {
      now_ += need;
      used = packet_left_;
    } else {
      const auto sent = static_cast<std::size_t>(std::floor((seg_end - now_) * bytes_per_s));
      used = std::min(sent, packet_left_);
      now_ = seg_end;
    }
    for (std::size_t i = 0; i < queues_.size(); ++i)
      if (!queues_[i].empty()) backlogged_up_s_[i] += now_ - t0;
    served_[serving] += static_cast<double>(used);
    InFlight& m = queues_[serving].front();
    m.remaining -= used;
    packet_left_ -= used;
    if (m.remaining == 0) completeMessage(serving, now_);
  }
}

}  // namespace hermes
