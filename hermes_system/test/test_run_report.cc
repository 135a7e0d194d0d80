// The run report and metrics.json lead with what merging gave: the one map the
// robots were placed in (robots, keyframes, landmarks, metres flown, extent), the
// loops between robots, the bytes sent against raw streaming and the cameras'
// images, and each robot's odometry ATE beside its ATE in the merged map. Three
// robots of the rendered hall (rendered_hall.h), unlimited link.
#include <gtest/gtest.h>

#include <cstdint>
#include <string>

#include <nlohmann/json.hpp>

#include "hermes/system/offline_run.h"
#include "hermes/system/run_results.h"
#include "support/hall_run.h"

using namespace hermes;

TEST(RunReport, LeadsWithTheOneMapTheRobotsWerePlacedIn) {
  auto run = test_support::makeHallRun(test_support::testRunParams(), "report");
  ASSERT_TRUE(run);
  ASSERT_TRUE(run->run());
  const system::RunResults r = system::evaluateRun(*run);
  const std::string report = system::formatReport(*run, r);
  std::printf("%s", report.c_str());

  const system::MapSummary& g = r.map;
  ASSERT_TRUE(r.metrics.agents_merged.has_value());
  EXPECT_EQ(g.robots, *r.metrics.agents_merged);
  EXPECT_EQ(g.robots, 3);
  EXPECT_EQ(g.keyframes, static_cast<std::int64_t>(run->server().map().keyframeCount()));
  EXPECT_EQ(g.landmarks, static_cast<std::int64_t>(run->server().map().landmarkCount()));
  EXPECT_GT(g.landmarks, 0);
  EXPECT_GT(g.loops_inter_robot, 0);
  EXPECT_LE(g.loops_inter_robot, r.metrics.loops_accepted.value_or(0));
  ASSERT_EQ(g.robot_path_m.size(), 3u);
  double sum = 0;
  for (const auto& [name, m] : g.robot_path_m) {
    EXPECT_GE(m, 0) << name;
    sum += m;
  }
  EXPECT_NEAR(sum, g.path_m, 1e-9);
  EXPECT_GT(g.path_m, 0);
  EXPECT_GT(g.extent_m.x(), 0);  // longest side first
  EXPECT_GE(g.extent_m.x(), g.extent_m.y());
  EXPECT_GE(g.extent_m.y(), g.extent_m.z());

  // The cameras' images: every frame fed, a grey stereo pair each.
  std::int64_t expected = 0;
  for (const system::OfflineAgent& a : run->agents()) {
    const PinholeIntrinsics& K = a.dataset->info().K;
    expected += static_cast<std::int64_t>(a.next) * 2 * K.width * K.height;
  }
  EXPECT_GT(expected, 0);
  EXPECT_EQ(r.camera_bytes, expected);
  EXPECT_LT(r.metrics.bytes_total.value_or(0), r.camera_bytes);
  // Raw streaming of the same windows: each robot's windows as cut, more than
  // the distilled submaps sent.
  std::int64_t windows = 0;
  for (const system::OfflineAgent& a : run->agents()) windows += a.pipeline->windows().window_bytes;
  EXPECT_EQ(r.raw_streaming_bytes, windows);
  EXPECT_GT(r.raw_streaming_bytes, r.metrics.bytes_total.value_or(0));

  // The report's first lines: the one map, then a row per robot with both errors.
  EXPECT_EQ(report.rfind("one map: 3 of 3 robots placed in one world frame", 0), 0u) << report;
  const std::size_t table = report.find("odometry (own frame)");
  ASSERT_NE(table, std::string::npos) << report;
  EXPECT_LT(report.find("between robots"), table);
  EXPECT_LT(report.find("raw streaming of the same maps"), table);
  EXPECT_LT(report.find("images the cameras took"), table);
  EXPECT_LT(table, report.find("uplink: "));  // the details come after
  for (const AgentMetrics& a : r.metrics.per_agent) EXPECT_NE(report.find("  " + a.agent, table), std::string::npos);
  EXPECT_NE(report.find("all robots", table), std::string::npos);

  // metrics.json: the keys it had, and the map's summary added beside them.
  const nlohmann::json j = system::resultsJson(r);
  for (const char* key : {"ate_rmse_m", "per_agent", "bytes_total", "kBps_mean", "kBps_peak", "loops_accepted",
                          "loops_rejected", "agents_merged", "timings_ms", "loop_accuracy", "loops_per_pair"})
    EXPECT_TRUE(j.contains(key)) << key;
  ASSERT_TRUE(j.contains("global_map"));
  const nlohmann::json& m = j["global_map"];
  EXPECT_EQ(m.at("robots").get<std::int64_t>(), g.robots);
  EXPECT_EQ(m.at("keyframes").get<std::int64_t>(), g.keyframes);
  EXPECT_EQ(m.at("landmarks").get<std::int64_t>(), g.landmarks);
  EXPECT_EQ(m.at("loops_inter_robot").get<std::int64_t>(), g.loops_inter_robot);
  EXPECT_DOUBLE_EQ(m.at("path_m").get<double>(), g.path_m);
  EXPECT_EQ(m.at("robot_path_m").size(), 3u);
  ASSERT_EQ(m.at("extent_m").size(), 3u);
  EXPECT_DOUBLE_EQ(m.at("extent_m")[0].get<double>(), g.extent_m.x());
  EXPECT_EQ(j.at("camera_bytes_total").get<std::int64_t>(), r.camera_bytes);
  EXPECT_EQ(j.at("raw_streaming_bytes_total").get<std::int64_t>(), r.raw_streaming_bytes);
}

// A run saves its map (saveMapToResume, hermes run's OUT/map); a second run of
// the same robots started on it (server.prior_map) places all three in the
// prior's world frame, and its report says it ran on a prior map.
TEST(RunReport, ASecondRunOnTheSavedMapPlacesItsRobotsInThePriorsFrame) {
  auto first = test_support::makeHallRun(test_support::testRunParams(), "prior_first");
  ASSERT_TRUE(first);
  ASSERT_TRUE(first->run());
  const std::string map_dir = ::testing::TempDir() + "/hermes_run_report_prior_map";
  ASSERT_TRUE(system::saveMapToResume(first->server(), map_dir));
  const std::size_t prior_keyframes = first->server().map().keyframeCount();

  system::SystemParams p = test_support::testRunParams();
  p.server.checkpoint.prior_map = map_dir;
  auto second = test_support::makeHallRun(p, "prior_second");
  ASSERT_TRUE(second);
  EXPECT_EQ(second->server().resumeReport().prior_map.rfind(map_dir, 0), 0u);
  ASSERT_TRUE(second->run());
  const system::RunResults r = system::evaluateRun(*second);
  const std::string report = system::formatReport(*second, r);
  std::printf("%s", report.c_str());
  EXPECT_EQ(r.map.robots, 3);
  EXPECT_EQ(r.map.prior_robots, 3);
  EXPECT_EQ(r.metrics.agents_merged.value_or(0), 3);
  EXPECT_GT(r.map.keyframes, static_cast<std::int64_t>(prior_keyframes));
  EXPECT_EQ(report.rfind("one map: 3 of 3 robots placed in one world frame of a prior map (3 robots before)", 0), 0u)
      << report;
  for (const AgentMetrics& a : r.metrics.per_agent) {
    ASSERT_TRUE(a.merged_ate_rmse_m) << a.agent;
    EXPECT_LT(*a.merged_ate_rmse_m, 0.05) << a.agent;
  }
}
