#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>

#include "hermes/core/bandwidth_log.h"
#include "hermes/core/config.h"
#include "hermes/core/metrics.h"

using namespace hermes;
using nlohmann::json;

namespace {

RunMetrics fullMetrics() {
  RunMetrics m;
  m.ate_rmse_m = 0.125;
  AgentMetrics a;
  a.agent = "agent_0";
  a.ate_rmse_m = 0.1;
  a.lost_rate = 0.02;
  a.keyframes = 120;
  a.landmarks = 4567;
  a.bytes = 1234567;
  a.submaps_sent = 30;
  a.submaps_applied = 29;
  a.submaps_deferred = 1;
  a.rpe_trans_rmse_m = 0.01;
  a.matched_poses = 900;
  a.frames_skipped = 3;
  a.frames_skipped_causes = {{"unreadable", 2}, {"wrong_size", 1}};
  m.per_agent.push_back(a);
  AgentMetrics b;  // an agent about which only bandwidth is known
  b.agent = "agent_1";
  b.bytes = 99;
  m.per_agent.push_back(b);
  m.bytes_total = 1234666;
  m.kBps_mean = 12.5;
  m.kBps_peak = 40.25;
  m.loops_accepted = 7;
  m.loops_rejected = 2;
  m.agents_merged = 2;
  m.timings_ms["tracking"] = {11.5, 20.25, 1000};
  m.alignment = "se3";
  m.T_gt_est = SE3(expSO3(Vec3(0.1, 0.2, 0.3)), Vec3(1, 2, 3));
  m.matched_poses = 900;
  m.incomplete = true;
  m.stopped_because = "interrupted at frame 12";
  return m;
}

std::string writeText(const std::string& name, const std::string& text) {
  const std::string path = ::testing::TempDir() + "/" + name;
  std::ofstream(path) << text;
  return path;
}

}  // namespace

TEST(TimingStats, MedianAndP95) {
  TimingStats ts;
  for (int i = 100; i >= 1; --i) ts.add("track", i);  // order must not matter
  ts.add("pgo", 4.0);
  TimingStats other;
  other.add("pgo", 2.0);
  ts.merge(other);
  const auto s = ts.summary();
  ASSERT_EQ(s.size(), 2u);
  EXPECT_DOUBLE_EQ(s.at("track").median, 50.5);
  EXPECT_NEAR(s.at("track").p95, 95.05, 1e-12);  // 1 + 0.95 * 99
  EXPECT_EQ(s.at("track").count, 100);
  EXPECT_DOUBLE_EQ(s.at("pgo").median, 3.0);
  EXPECT_EQ(ts.count("pgo"), 2u);
  EXPECT_EQ(ts.count("nothing"), 0u);
  EXPECT_DOUBLE_EQ(timing::percentile({}, 50), 0.0);
  EXPECT_DOUBLE_EQ(timing::percentile({7}, 95), 7.0);
}

TEST(TimingStats, AWindowSummarisesTheLastSamplesWithBoundedMemory) {
  TimingStats ts(100);
  for (int i = 1; i <= 10000; ++i) ts.add("track", i < 9901 ? 1000.0 : double(i - 9900));
  // The last 100 samples are 1..100: the 9900 slow ones before them are out of the window.
  const auto s = ts.summary();
  EXPECT_DOUBLE_EQ(s.at("track").median, 50.5);
  EXPECT_NEAR(s.at("track").p95, 95.05, 1e-12);
  EXPECT_EQ(s.at("track").count, 10000);  // every sample counted
  EXPECT_EQ(ts.count("track"), 10000u);
  EXPECT_LT(ts.samples().at("track").size(), 200u);  // below 2 W held
  EXPECT_GE(ts.samples().at("track").size(), 100u);
  // Merging into a windowed one keeps the window and the counts.
  TimingStats other;
  for (int i = 0; i < 500; ++i) other.add("track", 7.0);
  TimingStats copy = ts;
  copy.merge(other);
  EXPECT_EQ(copy.window(), 100u);
  EXPECT_DOUBLE_EQ(copy.summary().at("track").median, 7.0);
  EXPECT_EQ(copy.count("track"), 10500u);
  EXPECT_LT(copy.samples().at("track").size(), 200u);
}

TEST(MetricsJson, ContractKeysAlwaysPresentNullWhenNotApplicable) {
  RunMetrics empty;
  AgentMetrics a;
  a.agent = "solo";
  empty.per_agent.push_back(a);
  const json j = empty;
  for (const char* key : {"ate_rmse_m", "per_agent", "bytes_total", "kBps_mean", "kBps_peak",
                          "loops_accepted", "loops_rejected", "agents_merged", "timings_ms"})
    EXPECT_TRUE(j.contains(key)) << key;
  EXPECT_TRUE(j["ate_rmse_m"].is_null());
  EXPECT_TRUE(j["timings_ms"].is_object());
  for (const char* key : {"agent", "ate_rmse_m", "lost_rate", "keyframes", "landmarks", "bytes",
                          "submaps_sent", "submaps_applied", "submaps_deferred"})
    EXPECT_TRUE(j["per_agent"][0].contains(key)) << key;
  EXPECT_TRUE(j["per_agent"][0]["bytes"].is_null());
  // Extras are omitted when they do not apply.
  EXPECT_FALSE(j.contains("alignment"));
  EXPECT_FALSE(j["per_agent"][0].contains("rpe_trans_rmse_m"));
}

TEST(MetricsJson, FileRoundTrip) {
  const RunMetrics m = fullMetrics();
  const std::string path = ::testing::TempDir() + "/metrics.json";
  ASSERT_TRUE(writeMetricsJson(path, m));
  auto r = readMetricsJson(path);
  ASSERT_TRUE(r.ok()) << r.error();
  EXPECT_EQ(json(*r), json(m));  // everything survives, including the nulls
  EXPECT_DOUBLE_EQ(*r->ate_rmse_m, 0.125);
  ASSERT_EQ(r->per_agent.size(), 2u);
  EXPECT_EQ(r->per_agent[0].agent, "agent_0");
  EXPECT_EQ(*r->per_agent[0].bytes, 1234567);
  EXPECT_FALSE(r->per_agent[1].ate_rmse_m.has_value());
  EXPECT_EQ(*r->per_agent[1].bytes, 99);
  EXPECT_DOUBLE_EQ(r->timings_ms.at("tracking").p95, 20.25);
  EXPECT_EQ(r->per_agent[0].frames_skipped_causes.at("wrong_size"), 1);
  EXPECT_TRUE(*r->incomplete);
  ASSERT_TRUE(r->T_gt_est.has_value());
  EXPECT_LT((r->T_gt_est->matrix() - m.T_gt_est->matrix()).norm(), 1e-12);
  // nlohmann's ADL route works too.
  const RunMetrics via = json(m).get<RunMetrics>();
  EXPECT_EQ(via.loops_accepted, 7);
}

TEST(MetricsJson, ErrorsNameFileAndField) {
  const std::string garbage = writeText("garbage.json", "{ \"ate_rmse_m\": 0.1, ");
  auto g = readMetricsJson(garbage);
  ASSERT_FALSE(g.ok());
  EXPECT_NE(g.error().find(garbage), std::string::npos) << g.error();

  json j = fullMetrics();
  j.erase("kBps_peak");
  const std::string missing = writeText("missing.json", j.dump());
  auto m = readMetricsJson(missing);
  ASSERT_FALSE(m.ok());
  EXPECT_NE(m.error().find(missing), std::string::npos) << m.error();
  EXPECT_NE(m.error().find("kBps_peak"), std::string::npos) << m.error();

  j = fullMetrics();
  j["per_agent"][1]["bytes"] = "lots";
  const std::string wrong = writeText("wrong.json", j.dump());
  auto w = readMetricsJson(wrong);
  ASSERT_FALSE(w.ok());
  EXPECT_NE(w.error().find("per_agent[1].bytes"), std::string::npos) << w.error();

  j = fullMetrics();
  j["per_agent"][0].erase("submaps_deferred");
  auto d = metricsFromJson(j, "inline");
  ASSERT_FALSE(d.ok());
  EXPECT_NE(d.error().find("per_agent[0].submaps_deferred"), std::string::npos) << d.error();

  j = fullMetrics();
  j["loops_accepted"] = 2.5;
  auto f = metricsFromJson(j, "inline");
  ASSERT_FALSE(f.ok());
  EXPECT_NE(f.error().find("loops_accepted"), std::string::npos) << f.error();

  j = fullMetrics();
  j["per_agent"][0]["frames_skipped_causes"]["unreadable"] = "two";
  auto c = metricsFromJson(j, "inline");
  ASSERT_FALSE(c.ok());
  EXPECT_NE(c.error().find("frames_skipped_causes.unreadable"), std::string::npos) << c.error();
  j = fullMetrics();
  j["incomplete"] = 1;
  EXPECT_FALSE(metricsFromJson(j, "inline").ok());

  EXPECT_FALSE(metricsFromJson(json::array(), "inline").ok());
  EXPECT_THROW(json::array().get<RunMetrics>(), std::invalid_argument);
  EXPECT_FALSE(readMetricsJson("/no/such/metrics.json").ok());
}

TEST(MetricsJson, FillAccuracyFromMultiAgentEvaluation) {
  Trajectory gt_a, gt_b, est_b;
  for (int i = 0; i < 200; ++i) {
    const double t = 0.05 * i;
    gt_a.push_back({t, SE3(expSO3(Vec3(0, 0, 0.3 * t)), Vec3(std::cos(t), std::sin(t), 0.1 * t))});
    gt_b.push_back({t, SE3(expSO3(Vec3(0, 0.1 * t, 0)), Vec3(2 - 0.2 * t, 0.5 * t, 1))});
    est_b.push_back({t, SE3(gt_b.back().T_W_B.quat(), gt_b.back().T_W_B.translation() +
                                                          Vec3(0, 0, 0.3))});
  }
  eval::EvalParams params;
  params.align = eval::AlignMode::kNone;
  auto ev = eval::evaluateAgents({{"a", gt_a, gt_a}, {"b", gt_b, est_b}}, params);
  ASSERT_TRUE(ev.ok()) << ev.error();
  RunMetrics m;
  AgentMetrics pre;  // an entry written earlier by the runner keeps its counters
  pre.agent = "b";
  pre.keyframes = 42;
  m.per_agent.push_back(pre);
  fillAccuracy(*ev, params, &m);
  ASSERT_EQ(m.per_agent.size(), 2u);
  EXPECT_EQ(m.per_agent[0].agent, "b");
  EXPECT_EQ(*m.per_agent[0].keyframes, 42);
  EXPECT_NEAR(*m.per_agent[0].ate_rmse_m, 0.3, 1e-12);
  EXPECT_NEAR(*m.per_agent[1].ate_rmse_m, 0.0, 1e-12);
  EXPECT_NEAR(*m.ate_rmse_m, 0.3 / std::sqrt(2.0), 1e-12);
  EXPECT_EQ(*m.alignment, "none");
  EXPECT_EQ(*m.matched_poses, 400);
  EXPECT_EQ(*m.rpe_delta_unit, "s");
}

TEST(EvalParams, ReadsAndValidatesConfig) {
  auto cfg = Config::fromString("eval:\n  align: sim3\n  max_dt: 0.01\n  rpe_delta_s: 2.0\n",
                                "inline.yaml");
  ASSERT_TRUE(cfg.ok()) << cfg.error();
  eval::EvalParams p;
  ASSERT_TRUE(p.read(*cfg)) << p.read(*cfg).error();
  EXPECT_EQ(p.align, eval::AlignMode::kSim3);
  EXPECT_DOUBLE_EQ(p.max_dt, 0.01);
  EXPECT_DOUBLE_EQ(p.rpe_delta_s, 2.0);
  auto bad = Config::fromString("eval:\n  align: affine\n", "bad.yaml");
  ASSERT_TRUE(bad.ok());
  EXPECT_FALSE(p.read(*bad).ok());
  auto neg = Config::fromString("eval:\n  rpe_delta_s: -1\n", "neg.yaml");
  ASSERT_TRUE(neg.ok());
  const Status s = eval::EvalParams{}.read(*neg);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().find("rpe_delta_s"), std::string::npos) << s.error();
}

TEST(BandwidthCsv, RoundTripSummaryAndErrors) {
  std::vector<BandwidthSample> s = {
      {0.0, "agent_0", 10.0, 100.0}, {0.0, "agent_1", 30.0, 100.0},
      {0.5, "agent_0", 50.0, 100.0}, {0.5, "agent_1", 20.0, 100.0},
      {1.0, "agent_0", 0.0, 0.0},    {1.0, "agent_1", 0.0, std::nullopt}};
  const std::string path = ::testing::TempDir() + "/bw.csv";
  ASSERT_TRUE(writeBandwidthCsv(path, s));
  auto r = readBandwidthCsv(path);
  ASSERT_TRUE(r.ok()) << r.error();
  ASSERT_EQ(r->size(), 6u);
  EXPECT_EQ((*r)[3].agent, "agent_1");
  EXPECT_DOUBLE_EQ((*r)[2].kBps, 50.0);
  EXPECT_FALSE((*r)[5].link_capacity_kBps.has_value());
  EXPECT_DOUBLE_EQ(*(*r)[4].link_capacity_kBps, 0.0);
  const BandwidthSummary sum = summarizeBandwidth(*r);
  EXPECT_EQ(sum.intervals, 3u);
  EXPECT_DOUBLE_EQ(sum.kBps_peak, 70.0);
  EXPECT_DOUBLE_EQ(sum.kBps_mean, 110.0 / 3.0);

  const std::string bad = writeText("bw_bad.csv", "time_s,agent,kBps,link_capacity_kBps\n"
                                                  "0,a,1,2\n0.5,a,fast,2\n");
  auto b = readBandwidthCsv(bad);
  ASSERT_FALSE(b.ok());
  EXPECT_NE(b.error().find(bad + ":3"), std::string::npos) << b.error();
  EXPECT_NE(b.error().find("kBps"), std::string::npos) << b.error();
  EXPECT_FALSE(readBandwidthCsv(writeText("bw_hdr.csv", "t,agent,kBps\n")).ok());
  EXPECT_FALSE(writeBandwidthCsv(path + ".bad", {{0.0, "a,b", 1.0, std::nullopt}}).ok());
}
