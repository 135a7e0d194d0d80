// Whole-system regression for the global map's accuracy: two robots fly the same
// route through the rendered hall (they meet all along, 30 s each), once as they
// are, then with one robot's odometry corrupted by the test hook while its
// observations, hence its loops, stay right: a 0.5 m / 10 deg relocalisation
// error mid-run, and a silent drift of 3 % of the distance over 20 s. The merged
// map must be no worse than each robot's own odometry, and must repair the
// corrupted robot: its merged error at most half its odometry error, the other
// robot barely disturbed.
#include <gtest/gtest.h>

#include <string>

#include "hermes/system/offline_run.h"
#include "hermes/system/run_results.h"
#include "support/hall_run.h"

using namespace hermes;

namespace {

/// The run's results; `report` (optional) receives its printed report.
system::RunResults runMeeting(const system::SystemParams& params, const std::string& tag,
                              std::string* report = nullptr) {
  auto run = test_support::makeMeetingRun(params, tag);
  if (!run) return {};
  EXPECT_TRUE(run->run());
  system::RunResults r = system::evaluateRun(*run);
  const std::string text = system::formatReport(*run, r);
  std::printf("[%s]\n%s", tag.c_str(), text.c_str());
  if (report) *report = text;
  return r;
}

const AgentMetrics* agentMetrics(const system::RunResults& r, const std::string& name) {
  for (const AgentMetrics& a : r.metrics.per_agent)
    if (a.agent == name) return &a;
  return nullptr;
}

}  // namespace

TEST(MergeRepairsOdometry, CleanAndCorruptedRobots) {
  std::string report;
  const system::RunResults clean = runMeeting(test_support::testRunParams(), "clean", &report);
  ASSERT_EQ(clean.metrics.agents_merged.value_or(0), 2);
  EXPECT_EQ(report.find("injected"), std::string::npos) << report;
  for (const AgentMetrics& a : clean.metrics.per_agent) {
    ASSERT_TRUE(a.raw_ate_rmse_m && a.merged_ate_rmse_m) << a.agent;
    // One common alignment for both robots, still no worse than each one's own odometry.
    EXPECT_LE(*a.merged_ate_rmse_m, 1.05 * *a.raw_ate_rmse_m + 0.002) << a.agent;
    // Each robot was told its place in the world after the merges (world <- odom)
    // and knew it, through its own odometry, about as well as the merged map does.
    EXPECT_GE(a.global_pose_updates.value_or(0), 3) << a.agent;
    ASSERT_TRUE(a.global_pose_final_m && a.global_pose_rmse_m) << a.agent;
    EXPECT_LT(*a.global_pose_final_m, 0.03) << a.agent;
    EXPECT_LT(*a.global_pose_rmse_m, 0.03) << a.agent;
  }

  const AgentMetrics* other_clean = agentMetrics(clean, "MH_01_easy");
  ASSERT_TRUE(other_clean && other_clean->merged_ate_rmse_m);
  for (const std::string kind : {"jump", "drift"}) {
    system::SystemParams p = test_support::testRunParams();
    p.corrupt.agent = "MH_02_easy";
    p.corrupt.kind = kind;
    p.corrupt.at_s = kind == "jump" ? 15 : 5;
    p.corrupt.drift_duration_s = 20;
    const system::RunResults bad = runMeeting(p, kind, &report);
    ASSERT_EQ(bad.metrics.agents_merged.value_or(0), 2) << kind;
    // The report says what was injected, beside the numbers it moves.
    EXPECT_NE(report.find(std::string("injected  MH_02_easy's odometry ") + (kind == "jump" ? "jumps" : "drifts")),
              std::string::npos)
        << report;
    const AgentMetrics* victim = agentMetrics(bad, "MH_02_easy");
    ASSERT_TRUE(victim && victim->raw_ate_rmse_m && victim->merged_ate_rmse_m) << kind;
    EXPECT_GT(*victim->raw_ate_rmse_m, 0.05) << kind << ": the hook should have corrupted the odometry";
    EXPECT_LE(*victim->merged_ate_rmse_m, 0.5 * *victim->raw_ate_rmse_m) << kind;
    // The corrupted robot gets its place back: at its last frame it knows where it
    // is in the world better than its odometry does (measured: jump 1.5 cm
    // against 19.9 cm; drift 6.6 cm against 7.3 cm: the drift goes on between the
    // updates, one per merged window, so its bound is looser). The run is the same
    // on every machine load (distill.solver_limits auto: work limits in the offline
    // runner).
    ASSERT_TRUE(victim->global_pose_final_m) << kind;
    EXPECT_LE(*victim->global_pose_final_m, (kind == "jump" ? 0.5 : 0.92) * *victim->raw_ate_rmse_m) << kind;
    const AgentMetrics* other = agentMetrics(bad, "MH_01_easy");
    ASSERT_TRUE(other && other->merged_ate_rmse_m) << kind;
    EXPECT_LE(*other->merged_ate_rmse_m, 1.2 * *other_clean->merged_ate_rmse_m + 0.005) << kind;
  }
}
