#include <gtest/gtest.h>

#include "hermes/agent/bandwidth_monitor.h"
#include "hermes/agent/monitor_replay.h"
#include "hermes/core/emulated_link.h"

using namespace hermes;
using namespace hermes::agent;


namespace {
double estimateAt(const std::vector<MonitorCurvePoint>& curve, double t) {
  for (const MonitorCurvePoint& c : curve)
    if (c.t >= t) return c.estimate_mbitps;
  return curve.back().estimate_mbitps;
}
}  // namespace

TEST(BandwidthMonitor, ConvergesOnConstantLink) {
  const auto curve = replayMonitor(LinkTrace::constant(10.0, 5.0), {}, {}, 60.0);
  EXPECT_NEAR(estimateAt(curve, 59.0), 10.0, 2.0);
}

TEST(BandwidthMonitor, DetectsOutageAndRecovers) {
  auto trace = LinkTrace::fromString(
      "time_s,rate_mbitps,latency_ms,loss\n0,10,5,0\n40,0,5,0\n70,10,5,0\n", "t");
  ASSERT_TRUE(trace.ok());
  const auto curve = replayMonitor(*trace, {}, {}, 120.0);
  EXPECT_GT(estimateAt(curve, 39.0), 8.0);
  EXPECT_EQ(estimateAt(curve, 50.0), 0.0);  // outage detected well within 10 s
  EXPECT_NEAR(estimateAt(curve, 115.0), 10.0, 2.0);
}

// A link far slower than the initial guess: the first message is overdue long
// before its ack, and the estimate falls to bytes / time in transfer.
TEST(BandwidthMonitor, OverdueMessageBoundsTheEstimate) {
  BandwidthMonitorParams p;
  p.initial_bps = 125000;
  BandwidthMonitor m(p);
  m.onSend(1, 80000, 0.0);
  EXPECT_DOUBLE_EQ(m.estimate(0.5), 125000);  // not overdue yet (2 x 0.64 s + latency)
  EXPECT_NEAR(m.estimate(5.0), 16000, 1e-6);  // at most 80 kB in 5 s
  EXPECT_NEAR(m.estimate(20.0), 4000, 1e-6);
  EXPECT_FALSE(m.outage(20.0));  // the rate floor keeps a slow transfer from an outage
  m.onAck(1, 40.0);              // 2 kB/s in truth
  EXPECT_NEAR(m.estimate(40.0), 2000, 1e-6);
  // A message not yet overdue (its transfer time + latency) does not cap it.
  m.onSend(2, 1000, 40.0);
  EXPECT_NEAR(m.estimate(40.3), 2000, 1e-6);
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
  // The trace: 30 -> 10 -> 2 -> 0 (30 s outage) -> 20 Mbit/s.
  auto trace = LinkTrace::fromString(
      "time_s,rate_mbitps,latency_ms,loss\n0,30,5,0\n60,10,5,0\n120,2,5,0\n180,0,5,0\n"
      "210,20,5,0\n",
      "steps");
  ASSERT_TRUE(trace.ok());
  const BandwidthMonitorParams mp;
  const MonitorReplayParams rp;
  const auto curve = replayMonitor(*trace, mp, rp, 270.0);
  ASSERT_TRUE(writeMonitorCurveCsv(curve, ::testing::TempDir() + "/monitor_steps.csv").ok());
  const auto steps = stepResponses(curve, rp.window_s);
  ASSERT_EQ(steps.size(), 5u);
  for (const MonitorStepResponse& r : steps) {
    std::printf("change at %5.0f s to %4.0f Mbit/s: settled after %5.2f s, error two windows later %.3f\n",
                r.t_change, r.rate_mbitps, r.settle_s, r.error_after_two_windows);
    if (r.rate_mbitps > 0) {
      EXPECT_LE(r.error_after_two_windows, 0.2) << "change at " << r.t_change;
      EXPECT_GE(r.settle_s, 0) << "never settled after the change at " << r.t_change;
      EXPECT_LE(r.settle_s, 2 * rp.window_s) << "change at " << r.t_change;
    }
  }
  // Outage (t = 180): detected within T_out after the last message due before it.
  double detected = -1;
  for (const MonitorCurvePoint& c : curve)
    if (c.t >= 180 && c.outage) { detected = c.t; break; }
  ASSERT_GE(detected, 0) << "outage never detected";
  std::printf("outage at 180 s detected at %.2f s (T_out %.1f s)\n", detected, mp.outage_timeout_s);
  EXPECT_LE(detected - 180.0, mp.outage_timeout_s + rp.window_s);
  for (const MonitorCurvePoint& c : curve)
    if (c.t >= detected && c.t < 210) {
      EXPECT_EQ(c.estimate_mbitps, 0.0) << "t=" << c.t;
    }
}

TEST(BandwidthMonitor, ReplayParamsAndStepsOnAFlatTrace) {
  EXPECT_FALSE(MonitorReplayParams{.window_s = 0}.validate().ok());
  auto trace = LinkTrace::fromString("time_s,rate_mbitps,latency_ms,loss\n0,8,5,0\n", "flat");
  ASSERT_TRUE(trace.ok());
  const auto curve = replayMonitor(*trace, BandwidthMonitorParams{}, MonitorReplayParams{}, 60);
  const auto steps = stepResponses(curve, 5.0);
  ASSERT_EQ(steps.size(), 1u);
  EXPECT_NEAR(steps[0].rate_mbitps, 8.0, 1e-9);
  EXPECT_GE(steps[0].settle_s, 0);
  EXPECT_FALSE(writeMonitorCurveCsv(curve, "/nonexistent_dir/x.csv").ok());
}
