#include "hermes/agent/relay_split.h"

#include <algorithm>
#include <cmath>

#include "hermes/core/wire_format.h"

namespace hermes::agent {

Status RelayParams::read(const Config& c) {
  for (Status s : {c.get("relay.enabled", &enabled), c.get("relay.min_mbitps", &min_mbitps),
                   c.get("relay.own_min_share", &own_min_share), c.get(kCredibilityWts, &w_ts),
                   c.get(kCredibilityWmc, &w_mc), c.get("relay.ack_retry_s", &ack_retry_s)})
    if (!s) return s;
  return validate();
}

Status RelayParams::validate() const {
  if (!(min_mbitps >= 0) || !std::isfinite(min_mbitps))
    return Error{"relay.min_mbitps must be >= 0 Mbit/s"};
  if (!(own_min_share >= 0 && own_min_share < 1)) return Error{"relay.own_min_share must be in [0, 1)"};
  if (!(w_ts >= 0) || !(w_mc >= 0) || !(w_ts + w_mc > 0) || !std::isfinite(w_ts + w_mc))
    return Error{std::string(kCredibilityWts) + " and " + kCredibilityWmc + " must be >= 0 and not both 0"};
  if (!(ack_retry_s > 0) || !std::isfinite(ack_retry_s)) return Error{"relay.ack_retry_s must be > 0"};
  return Status::Ok();
}

void RelayParams::write(ConfigWriter& w) const {
  w.set("relay.enabled", enabled);
  w.set("relay.min_mbitps", min_mbitps);
  w.set("relay.own_min_share", own_min_share);
  w.set(kCredibilityWts, w_ts);
  w.set(kCredibilityWmc, w_mc);
  w.set("relay.ack_retry_s", ack_retry_s);
}

void StreamEvidence::onFrame(const std::vector<std::uint8_t>& frame, double now, bool duplicate) {
  if (first_t_ < 0) first_t_ = now;
  bytes_ += static_cast<double>(frame.size());
  if (duplicate) {
    ++duplicates_;
    return;
  }
  ++frames_;
  // Map connectivity from the submap itself; a frame that does not decode
  // (damaged: the server will refuse it) adds nothing.
  auto header = peekFrame(frame.data(), frame.size());
  if (!header) return;
  auto submap = decodeSubmap(frame.data(), std::min(frame.size(), header->frameBytes()));
  if (!submap) return;
  landmarks_ += static_cast<double>(submap->landmarks.size());
  observations_ += static_cast<double>(submap->observationCount());
}

RelayStream StreamEvidence::stream(double now, bool own) const {
  RelayStream s;
  s.own = own;
  const std::size_t arrivals = frames_ + duplicates_;
  s.success_rate = arrivals > 0 ? double(frames_) / double(arrivals) : 1.0;
  s.bytes_per_s = first_t_ >= 0 && now > first_t_ ? bytes_ / (now - first_t_) : 0.0;
  s.obs_per_landmark = landmarks_ > 0 ? observations_ / landmarks_ : 0.0;
  return s;
}

std::vector<StreamShare> splitUplink(const RelayParams& p, const std::vector<RelayStream>& streams) {
  std::vector<StreamShare> out(streams.size());
  if (streams.empty()) return out;
  double max_rate = 0, max_opl = 0;
  for (const RelayStream& s : streams) {
    max_rate = std::max(max_rate, s.bytes_per_s);
    max_opl = std::max(max_opl, s.obs_per_landmark);
  }
  double sum = 0;
  for (std::size_t i = 0; i < streams.size(); ++i) {
    const RelayStream& s = streams[i];
    StreamShare& o = out[i];
    o.ts = max_rate > 0 ? std::clamp(s.success_rate, 0.0, 1.0) * s.bytes_per_s / max_rate : 0.0;
    o.mc = max_opl > 0 ? s.obs_per_landmark / max_opl : 0.0;
    o.c = p.w_ts * o.ts + p.w_mc * o.mc;
    o.weight = std::max(o.c, kMinStreamWeight);
    o.guaranteed_Bps = s.own ? 0.0 : p.minBps();
    sum += o.weight;
  }
  for (StreamShare& o : out) o.weight /= sum;
  // The relay's own map keeps at least own_min_share; the others give way in proportion.
  double own = 0;
  for (std::size_t i = 0; i < streams.size(); ++i)
    if (streams[i].own) own += out[i].weight;
  if (own > 0 && own < p.own_min_share && own < 1) {
    const double others = 1 - own;
    for (std::size_t i = 0; i < streams.size(); ++i)
      out[i].weight *= streams[i].own ? p.own_min_share / own : (1 - p.own_min_share) / others;
  }
  return out;
}

}  // namespace hermes::agent
