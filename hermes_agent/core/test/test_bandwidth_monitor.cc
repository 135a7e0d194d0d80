#include <gtest/gtest.h>

#include "hermes/agent/bandwidth_monitor.h"
#include "hermes/core/emulated_link.h"

using namespace hermes;
using namespace hermes::agent;

namespace {
// Drives the monitor like an agent: every 5 s it sends a window whose size is
// the planning rate × 5 s × 0.8, split into a few messages, over the link.
struct Sim {
  SharedLink link;
  BandwidthMonitor monitor;
  std::uint64_t next_id = 0;
  std::vector<std::pair<double, double>> curve;  // (t, estimate bps)
  explicit Sim(LinkTrace trace) : link(std::move(trace), 1, 3) {}

  void run(double t_end) {
    double next_window = 0;
    for (double t = 0; t < t_end; t += 0.05) {
      if (t >= next_window) {
        const double budget = 0.8 * monitor.planningRate(t) * 5.0;
        const double backlog = static_cast<double>(monitor.outstandingBytes());
        const double bytes = std::max(20000.0, budget - backlog);
        const bool delivered_all = backlog < 1.0;
        monitor.onWindowDelivered(delivered_all);
        for (int k = 0; k < 4; ++k) {
          LinkMessage m;
          m.id = next_id++;
          m.bytes = static_cast<std::size_t>(bytes / 4);
          monitor.onSend(m.id, m.bytes, t);
          link.send(m, t);
        }
        next_window += 5.0;
      }
      for (const auto& d : link.advanceTo(t)) {
        if (d.lost) continue;
        const double ack = link.ackArrival(d.arrival_time);
        if (ack >= 0) monitor.onAck(d.message.id, ack);
      }
      curve.emplace_back(t, monitor.estimate(t));
    }
  }
  double estimateAt(double t) const {
    for (const auto& [ct, e] : curve)
      if (ct >= t) return e;
    return curve.back().second;
  }
};
}  // namespace

TEST(BandwidthMonitor, ConvergesOnConstantLink) {
  Sim sim(LinkTrace::constant(10.0, 5.0));
  sim.run(60.0);
  const double truth = 10e6 / 8;
  EXPECT_NEAR(sim.estimateAt(59.0), truth, 0.2 * truth);
}

TEST(BandwidthMonitor, DetectsOutageAndRecovers) {
  auto trace = LinkTrace::fromString(
      "time_s,rate_mbitps,latency_ms,loss\n0,10,5,0\n40,0,5,0\n70,10,5,0\n", "t");
  ASSERT_TRUE(trace.ok());
  Sim sim(*trace);
  sim.run(120.0);
  EXPECT_GT(sim.estimateAt(39.0), 0.8 * 1.25e6);
  EXPECT_EQ(sim.estimateAt(50.0), 0.0);  // outage detected well within 10 s
  EXPECT_NEAR(sim.estimateAt(115.0), 1.25e6, 0.2 * 1.25e6);
}

TEST(BandwidthMonitor, ParamsValidate) {
  BandwidthMonitorParams p;
  p.probe_factor = 0.5;
  EXPECT_FALSE(p.validate().ok());
  auto c = Config::fromString("uplink:\n  monitor:\n    window_s: -1\n", "m.yaml");
  ASSERT_TRUE(c.ok());
  BandwidthMonitorParams q;
  EXPECT_FALSE(q.read(*c).ok());
}
