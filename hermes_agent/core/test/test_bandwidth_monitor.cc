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

// Issue trace: 30 -> 10 -> 2 -> 0 (30 s outage) -> 20 Mbit/s. The estimate must be
// within 20 % of the true rate within two 5-s windows after each change, and the
// outage detected within the timeout.
TEST(BandwidthMonitor, FollowsStepTrace) {
  auto trace = LinkTrace::fromString(
      "time_s,rate_mbitps,latency_ms,loss\n0,30,5,0\n60,10,5,0\n120,2,5,0\n180,0,5,0\n"
      "210,20,5,0\n",
      "steps");
  ASSERT_TRUE(trace.ok());
  Sim sim(*trace);
  sim.run(270.0);
  const std::string csv = ::testing::TempDir() + "/monitor_steps.csv";
  if (std::FILE* f = std::fopen(csv.c_str(), "w")) {
    std::fprintf(f, "time_s,true_mbitps,estimate_mbitps\n");
    for (const auto& [t, e] : sim.curve)
      std::fprintf(f, "%.2f,%.3f,%.3f\n", t, trace->at(t).rate_mbitps, e * 8e-6);
    std::fclose(f);
  }
  struct Check { double t_change, rate; };
  for (const Check c : {Check{0, 30}, Check{60, 10}, Check{120, 2}, Check{210, 20}}) {
    const double t = c.t_change + 10.0 + 0.5;  // two windows later
    const double est = sim.estimateAt(t) * 8e-6;
    EXPECT_NEAR(est, c.rate, 0.2 * c.rate) << "at t=" << t << " (change at " << c.t_change << ")";
  }
  EXPECT_EQ(sim.estimateAt(180.0 + 3.0 + 5.0), 0.0);  // outage seen within T_out + one window
}
