// The server killed mid-run (`hermes run --server-restart-at S`): three robots
// in the rendered hall, the server destroyed twice without a clean shutdown and
// re-created from its checkpoint directory. Every submap is applied exactly
// once, all robots merge, and the merged ATE stays within noise of the same run
// without restarts.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "hermes/system/offline_run.h"
#include "hermes/system/run_results.h"
#include "support/hall_run.h"

using namespace hermes;

namespace {

struct Outcome {
  system::RunResults results;
  std::vector<std::size_t> submitted;
};

Outcome runOnce(const system::SystemParams& params, const std::string& tag,
                std::unique_ptr<system::OfflineRun>* keep) {
  auto run = test_support::makeHallRun(params, "restart_" + tag);
  EXPECT_TRUE(run);
  if (!run) return {};
  Status s = run->run();
  EXPECT_TRUE(s) << s.error();
  Outcome o;
  o.results = system::evaluateRun(*run);
  std::printf("[%s]\n%s", tag.c_str(), system::formatReport(*run, o.results).c_str());
  for (const system::OfflineAgent& a : run->agents()) {
    const auto& up = a.pipeline->uplink()->stats();
    o.submitted.push_back(up.submitted);
    EXPECT_GT(up.submitted, 0u) << a.name;
    EXPECT_EQ(a.pipeline->uplink()->backlogBytes(), 0u) << a.name << ": spool not drained";
    EXPECT_TRUE(a.robot.has_value()) << a.name << " never reached the server";
    if (!a.robot) continue;
    const AgentStats* st = run->server().bookkeeper().stats(*a.robot);
    EXPECT_EQ(st->submaps_applied, up.submitted) << a.name << ": not applied exactly once";
    EXPECT_EQ(st->submaps_accepted, st->submaps_applied) << a.name;
  }
  EXPECT_EQ(run->server().counters().merge_errors, 0u) << run->server().counters().last_error;
  EXPECT_EQ(run->server().counters().merged, run->server().receiverStats().accepted);
  if (keep) *keep = std::move(run);
  return o;
}

}  // namespace

TEST(ServerRestart, KilledTwiceMidRunEverySubmapOnceAllMergedSameAccuracy) {
  system::SystemParams params;
  params.run.agent.uplink.buffer.fsync = false;
  params.link.bandwidth_mbitps = 2;  // shared: a window takes ~0.5-1.5 s to cross
  const Outcome plain = runOnce(params, "plain", nullptr);

  // While the first windows (cut at 5 s) cross the link, and after the server
  // merged and checkpointed them, as the last windows (end of the clips) cross.
  params.clock.server_restart_at = {5.3, 10.2};
  params.clock.server_downtime_s = 1.0;
  std::unique_ptr<system::OfflineRun> run;
  const Outcome restarted = runOnce(params, "restarted", &run);
  ASSERT_TRUE(run);
  ASSERT_TRUE(restarted.results.durability.has_value());

  ASSERT_EQ(run->restarts().size(), 2u);
  std::size_t lost_down = 0;
  for (const system::ServerRestart& r : run->restarts()) {
    EXPECT_TRUE(r.problems.empty()) << r.problems.front();
    EXPECT_NEAR(r.up_at_s - r.down_at_s, 1.0, 0.02);
    EXPECT_GT(r.resume_ms, 0.0);
    lost_down += r.frames_lost_down;
  }
  EXPECT_FALSE(run->restarts()[1].checkpoint.empty()) << "the second restart found no checkpoint";
  // The restarts really cut deliveries: frames were lost and sent again.
  EXPECT_GT(lost_down, 0u);
  EXPECT_GE(restarted.results.durability->submaps_resent, lost_down);
  // The agents handed over the same windows; each was applied once (checked per
  // run above), also those the server had acknowledged before dying.
  EXPECT_EQ(restarted.submitted, plain.submitted);
  const RunMetrics& a = plain.results.metrics;
  const RunMetrics& b = restarted.results.metrics;
  ASSERT_TRUE(a.agents_merged && b.agents_merged);
  EXPECT_EQ(*a.agents_merged, 3);
  EXPECT_EQ(*b.agents_merged, 3);
  ASSERT_TRUE(a.ate_rmse_m && b.ate_rmse_m);
  std::printf("merged ATE: uninterrupted %.2f cm, restarted %.2f cm\n", *a.ate_rmse_m * 100,
              *b.ate_rmse_m * 100);
  EXPECT_NEAR(*b.ate_rmse_m, *a.ate_rmse_m, 0.25 * *a.ate_rmse_m + 0.005);

  // metrics.json covers the whole run and reports the restarts.
  const nlohmann::json j = system::resultsJson(restarted.results);
  ASSERT_TRUE(j.contains("server_restarts"));
  EXPECT_EQ(j["server_restarts"]["count"].get<int>(), 2);
  EXPECT_EQ(j["server_restarts"]["restarts"].size(), 2u);
  EXPECT_GT(j["server_durability"]["checkpoints"].get<int>(), 0);
  EXPECT_GT(j["server_durability"]["last_checkpoint_bytes"].get<int>(), 0);
  std::size_t submitted = 0;
  for (std::size_t n : restarted.submitted) submitted += n;
  EXPECT_EQ(j["server_durability"]["submaps_applied"].get<std::size_t>(), submitted);
  EXPECT_TRUE(j["timings_ms"].contains("checkpoint"));
  std::printf("%s\n", j["server_restarts"].dump(1).c_str());
  std::printf("%s\n", j["server_durability"].dump(1).c_str());
}
