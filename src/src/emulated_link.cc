#include "hermes/core/emulated_link.h"

#include <algorithm>
#include <cmath>

namespace hermes {

SharedLink::SharedLink(LinkTrace trace, int senders, std::uint64_t seed, std::size_t packet_bytes)
    : trace_(std::move(trace)),
      queues_(static_cast<std::size_t>(senders)),
      transmitted_(static_cast<std::size_t>(senders), 0),
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
  queues_[msg.sender].push_back({std::move(msg), bytes});
}

double SharedLink::ackArrival(double now) {
  const LinkState s = trace_.at(now);
  if (s.rate_mbitps <= 0 || draw(s.loss)) return -1.0;
  return now + s.latency_ms * 1e-3;
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
    // Pick the packet to serve (round robin over senders with queued data).
    if (current_ < 0 || packet_left_ == 0) {
      current_ = -1;
      for (std::size_t k = 0; k < queues_.size(); ++k) {
        const int cand = (rr_next_ + static_cast<int>(k)) % static_cast<int>(queues_.size());
        if (!queues_[cand].empty()) {
          current_ = cand;
          rr_next_ = (cand + 1) % static_cast<int>(queues_.size());
          break;
        }
      }
      if (current_ < 0) {  // idle
        now_ = seg_end;
        continue;
      }
      packet_left_ = std::min(packet_bytes_, queues_[current_].front().remaining);
    }
    const double need = static_cast<double>(packet_left_) / bytes_per_s;
    if (now_ + need <= seg_end) {
      now_ += need;
      InFlight& m = queues_[current_].front();
      m.remaining -= packet_left_;
      packet_left_ = 0;
      if (m.remaining == 0) completeMessage(current_, now_);
    } else {
      const auto sent = static_cast<std::size_t>(std::floor((seg_end - now_) * bytes_per_s));
      const std::size_t used = std::min(sent, packet_left_);
      packet_left_ -= used;
      queues_[current_].front().remaining -= used;
      now_ = seg_end;
    }
  }
}

}  // namespace hermes
