// Estimates the available uplink rate from what is really delivered (DESIGN §3):
// per-message delivery rate = bytes / (ack time - start of its transfer), where
// the transfer starts at max(send time, previous ack) while the link is busy.
// The sample is the lowest rate over the spans of the last 1..span_messages
// messages of the current busy period: after a stall (TCP head-of-line blocking
// behind a lost segment) a message's bytes arrive while its predecessor is still
// incomplete, so that message alone would look faster than the link; the span
// that starts before the stall does not;
// B̂ = max over the last `window_s` of samples, decayed when none arrive;
// outage when nothing is acknowledged for `outage_timeout_s` beyond the time the
// outstanding bytes should take → B̂ = 0. After a window whose budget was fully
// delivered in time, the next budget probes `probe_factor` higher.
// An overdue message bounds B̂ from above: a message of b bytes whose transfer
// began τ seconds ago and is still unacknowledged (τ > 2 × expected + latency_s)
// says the link carries less than b / τ -- so a link far slower than believed
// (the first windows, planned on the initial guess) is seen before any ack.
// It never reads a configured link rate.
#pragma once

#include <cstdint>
#include <deque>
#include <map>

#include "hermes/core/config.h"

namespace hermes::agent {

struct BandwidthMonitorParams {
  double window_s = 8.0;          ///< [s] max-filter window (< two 5-s windows: drops seen in time)
  double decay_tau_s = 10.0;      ///< [s] decay time constant once samples stop
  double outage_timeout_s = 3.0;  ///< [s] silence beyond the expected transfer time
  double probe_factor = 1.25;     ///< budget multiplier after a fully delivered window
  double initial_bps = 125000.0;  ///< [byte/s] guess before any sample (1 Mbit/s)
  int span_messages = 3;          ///< longest run of back-to-back messages a sample spans
  double latency_s = 0.5;         ///< [s] ack latency allowed before an overdue message bounds B̂

  Status read(const Config& c);
  Status validate() const;
  void write(ConfigWriter& w) const;
};

class BandwidthMonitor {
 public:
  explicit BandwidthMonitor(BandwidthMonitorParams p = {});

  void onSend(std::uint64_t id, std::size_t bytes, double t);
  /// Acknowledgement of message `id` at time t (unknown ids are ignored).
  void onAck(std::uint64_t id, double t);
  /// A message given up on (lost: will be resent under a new send).
  void onGiveUp(std::uint64_t id);
  /// Reports whether the last window's budget was delivered within its window.
  void onWindowDelivered(bool fully_in_time);

  /// Estimated available rate [byte/s] at time t (0 in an outage).
  double estimate(double t) const;
  /// Rate to plan the next window with: estimate × probe factor when probing.
  double planningRate(double t) const;
  bool outage(double t) const;
  std::size_t outstandingBytes() const;
  int samples() const { return static_cast<int>(sample_count_); }

 private:
  struct Sample {
    double t;
    double bps;
  };
  struct Outstanding {
    std::size_t bytes;
    double sent;
  };
  struct Delivered {  ///< a message of the current busy period
    double start, ack, bytes;
  };
  const Outstanding* oldestOutstanding() const;
  bool outage(double t, const Outstanding* oldest) const;
  /// Max-filtered / decayed rate from the samples alone (no outage, no bound).
  double sampledRate(double t) const;
  BandwidthMonitorParams p_;
  std::map<std::uint64_t, Outstanding> outstanding_;
  std::deque<Sample> samples_;
  std::deque<Delivered> busy_run_;  ///< last span_messages back-to-back deliveries
  double last_ack_ = -1e300;
  double last_sample_bps_ = 0;
  double last_sample_t_ = -1e300;
  bool probing_ = false;
  std::size_t sample_count_ = 0;
};

}  // namespace hermes::agent
