#include "hermes/agent/bandwidth_monitor.h"

#include <algorithm>
#include <cmath>

namespace hermes::agent {

Status BandwidthMonitorParams::read(const Config& c) {
  for (auto [key, field] : {std::pair{"uplink.monitor.window_s", &window_s},
                            std::pair{"uplink.monitor.decay_tau_s", &decay_tau_s},
                            std::pair{"uplink.monitor.outage_timeout_s", &outage_timeout_s},
                            std::pair{"uplink.monitor.probe_factor", &probe_factor},
                            std::pair{"uplink.monitor.initial_bps", &initial_bps},
                            std::pair{"uplink.monitor.latency_s", &latency_s}}) {
    if (Status s = c.get(key, field); !s) return s;
  }
  if (Status s = c.get("uplink.monitor.span_messages", &span_messages); !s) return s;
  return validate();
}

Status BandwidthMonitorParams::validate() const {
  if (!(window_s > 0)) return Error{"uplink.monitor.window_s must be > 0"};
  if (!(decay_tau_s > 0)) return Error{"uplink.monitor.decay_tau_s must be > 0"};
  if (!(outage_timeout_s > 0)) return Error{"uplink.monitor.outage_timeout_s must be > 0"};
  if (!(probe_factor >= 1.0)) return Error{"uplink.monitor.probe_factor must be >= 1"};
  if (!(initial_bps > 0)) return Error{"uplink.monitor.initial_bps must be > 0"};
  if (span_messages < 1) return Error{"uplink.monitor.span_messages must be >= 1"};
  if (!(latency_s >= 0)) return Error{"uplink.monitor.latency_s must be >= 0"};
  return Status::Ok();
}

void BandwidthMonitorParams::write(ConfigWriter& w) const {
  w.set("uplink.monitor.window_s", window_s);
  w.set("uplink.monitor.decay_tau_s", decay_tau_s);
  w.set("uplink.monitor.outage_timeout_s", outage_timeout_s);
  w.set("uplink.monitor.probe_factor", probe_factor);
  w.set("uplink.monitor.initial_bps", initial_bps);
  w.set("uplink.monitor.span_messages", span_messages);
  w.set("uplink.monitor.latency_s", latency_s);
}

BandwidthMonitor::BandwidthMonitor(BandwidthMonitorParams p) : p_(p) {
  HERMES_CHECK(p_.validate().ok(), p_.validate().error());
}

void BandwidthMonitor::onSend(std::uint64_t id, std::size_t bytes, double t) {
  outstanding_[id] = {bytes, t};
}

void BandwidthMonitor::onGiveUp(std::uint64_t id) { outstanding_.erase(id); }

void BandwidthMonitor::onAck(std::uint64_t id, double t) {
  auto it = outstanding_.find(id);
  if (it == outstanding_.end()) return;
  // While the link is busy, this message's transfer began when the previous
  // one was acknowledged, not when it was queued.
  const double start = std::max(it->second.sent, last_ack_);
  // A message sent after the last ack found the link idle: a new busy period.
  if (!busy_run_.empty() && start > busy_run_.back().ack) busy_run_.clear();
  busy_run_.push_back({start, t, static_cast<double>(it->second.bytes)});
  while (static_cast<int>(busy_run_.size()) > p_.span_messages) busy_run_.pop_front();
  double bps = -1;  // lowest rate over the spans ending with this message
  double bytes = 0;
  for (auto d = busy_run_.rbegin(); d != busy_run_.rend(); ++d) {
    bytes += d->bytes;
    const double dt = t - d->start;
    if (dt > 1e-6) bps = bps < 0 ? bytes / dt : std::min(bps, bytes / dt);
  }
  if (bps > 0) {
    samples_.push_back({t, bps});
    last_sample_bps_ = bps;
    last_sample_t_ = t;
    ++sample_count_;
    while (!samples_.empty() && samples_.front().t < t - p_.window_s) samples_.pop_front();
  }
  last_ack_ = std::max(last_ack_, t);
  outstanding_.erase(it);
}

void BandwidthMonitor::onWindowDelivered(bool fully_in_time) { probing_ = fully_in_time; }

std::size_t BandwidthMonitor::outstandingBytes() const {
  std::size_t n = 0;
  for (const auto& [id, o] : outstanding_) n += o.bytes;
  return n;
}

const BandwidthMonitor::Outstanding* BandwidthMonitor::oldestOutstanding() const {
  const Outstanding* oldest = nullptr;
  for (const auto& [id, o] : outstanding_)
    if (!oldest || o.sent < oldest->sent) oldest = &o;
  return oldest;
}

bool BandwidthMonitor::outage(double t) const { return outage(t, oldestOutstanding()); }

bool BandwidthMonitor::outage(double t, const Outstanding* oldest) const {
  if (!oldest) return false;
  // The next ack is due one transfer time of the oldest outstanding message
  // after the link last made progress; silence beyond that + T_out is an outage.
  const double since = std::max(oldest->sent, last_ack_);
  const double rate = std::max(last_sample_bps_, p_.initial_bps * 0.01);
  const double expected = static_cast<double>(oldest->bytes) / rate;
  return t - since > p_.outage_timeout_s + expected;
}

double BandwidthMonitor::sampledRate(double t) const {
  if (sample_count_ == 0) return p_.initial_bps;
  double best = 0;
  for (const auto& s : samples_)
    if (s.t > t - p_.window_s && s.t <= t) best = std::max(best, s.bps);
  if (best > 0) return best;
  // No sample in the window: decay the last known rate.
  const double silent = t - last_sample_t_ - p_.window_s;
  return last_sample_bps_ * std::exp(-std::max(0.0, silent) / p_.decay_tau_s);
}

double BandwidthMonitor::estimate(double t) const {
  const Outstanding* oldest = oldestOutstanding();
  if (outage(t, oldest)) return 0.0;
  double rate = sampledRate(t);
  // The oldest unacknowledged message has been in transfer since max(sent,
  // last ack); once clearly overdue at `rate` (twice its transfer time plus the
  // ack latency: queueing alone can delay it past once), the link cannot
  // be carrying more than its bytes over that time.
  if (oldest && rate > 0) {
    const double since = std::max(oldest->sent, last_ack_);
    const double bytes = static_cast<double>(oldest->bytes);
    const double elapsed = t - since;
    if (elapsed > 2.0 * bytes / rate + p_.latency_s) rate = std::min(rate, bytes / elapsed);
  }
  return rate;
}

double BandwidthMonitor::planningRate(double t) const {
  return estimate(t) * (probing_ ? p_.probe_factor : 1.0);
}

}  // namespace hermes::agent
