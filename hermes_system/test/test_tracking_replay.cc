// Tracking record / replay in the offline runner (issue 18): a run that
// replays the recorded tracking gives the same run as the one that recorded
// it, and, since the recording does not depend on the variant, the same run as
// a live run of another variant. Stale recordings are refused.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "hermes/system/offline_run.h"
#include "hermes/system/run_results.h"
#include "hermes/system/tracking_record.h"
#include "support/hall_run.h"
#include "support/rendered_hall.h"

using namespace hermes;
namespace fs = std::filesystem;

namespace {

const std::vector<std::size_t> kFrames = {0, 0, 0};  // all 100 frames each

system::SystemParams params(const std::string& strategy) {
  system::SystemParams p = test_support::testRunParams();
  p.link.bandwidth_mbitps = 2;  // the distiller has to choose
  if (!strategy.empty()) p.run.agent.distill.strategy = strategy;  // "": Hermes (the default)
  // No wall-clock limit that binds: the selections depend on nothing but the input.
  p.run.agent.distill.milp_time_limit_s = 60;
  p.run.agent.distill.trim_time_limit_s = 60;
  return p;
}

struct Outcome {
  std::vector<Trajectory> odometry, global;
  std::vector<std::int64_t> bytes, sent;
  std::vector<std::size_t> acked;
  std::vector<std::optional<double>> raw_ate;
  std::vector<BandwidthSample> bandwidth;
  std::size_t merged = 0;
  std::optional<std::int64_t> loops;
  std::optional<double> ate;
};

Outcome runOnce(const system::SystemParams& p, const std::string& tag,
                const std::vector<std::size_t>& frames = kFrames) {
  Outcome o;
  auto run = test_support::makeHallRun(p, tag, frames);
  if (!run) return o;
  Status s = run->run();
  EXPECT_TRUE(s) << s.error();
  const system::RunResults r = system::evaluateRun(*run);
  for (const system::OfflineAgent& a : run->agents()) {
    o.odometry.push_back(a.pipeline->trajectory());
    o.global.push_back(a.global_track);
    o.acked.push_back(a.acked);
  }
  for (const AgentMetrics& a : r.metrics.per_agent) {
    o.bytes.push_back(a.bytes.value_or(-1));
    o.sent.push_back(a.submaps_sent.value_or(-1));
    o.raw_ate.push_back(a.raw_ate_rmse_m);
  }
  o.bandwidth = run->bandwidth();
  o.merged = run->server().counters().merged;
  o.loops = r.metrics.loops_accepted;
  o.ate = r.metrics.ate_rmse_m;
  return o;
}

void expectSamePoses(const std::vector<Trajectory>& a, const std::vector<Trajectory>& b,
                     const char* what) {
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    ASSERT_EQ(a[i].size(), b[i].size()) << what << " agent " << i;
    for (std::size_t k = 0; k < a[i].size(); ++k) {
      ASSERT_EQ(a[i][k].t, b[i][k].t) << what << " agent " << i << " pose " << k;
      ASSERT_TRUE(a[i][k].T_W_B.matrix() == b[i][k].T_W_B.matrix())
          << what << " agent " << i << " pose " << k;
    }
  }
}

void expectSameRun(const Outcome& live, const Outcome& replay) {
  expectSamePoses(live.odometry, replay.odometry, "odometry");
  expectSamePoses(live.global, replay.global, "global track");
  EXPECT_EQ(live.bytes, replay.bytes);
  EXPECT_EQ(live.sent, replay.sent);
  EXPECT_EQ(live.acked, replay.acked);
  EXPECT_EQ(live.merged, replay.merged);
  EXPECT_EQ(live.loops, replay.loops);
  ASSERT_TRUE(live.ate && replay.ate);
  EXPECT_NEAR(*live.ate, *replay.ate, 1e-9);
  ASSERT_EQ(live.raw_ate.size(), replay.raw_ate.size());
  for (std::size_t i = 0; i < live.raw_ate.size(); ++i) {
    ASSERT_TRUE(live.raw_ate[i] && replay.raw_ate[i]);
    EXPECT_NEAR(*live.raw_ate[i], *replay.raw_ate[i], 1e-9);
  }
  ASSERT_EQ(live.bandwidth.size(), replay.bandwidth.size());
  for (std::size_t k = 0; k < live.bandwidth.size(); ++k)
    EXPECT_EQ(live.bandwidth[k].kBps, replay.bandwidth[k].kBps) << "sample " << k;
}

}  // namespace

TEST(TrackingReplay, ReplayGivesTheRecordedRunAndServesOtherVariants) {
  const std::string dir = ::testing::TempDir() + "/hermes_tracking_record";
  fs::remove_all(dir);

  system::SystemParams record = params("");
  record.clock.tracking_record_dir = dir;
  const Outcome live = runOnce(record, "track_record");
  ASSERT_FALSE(live.odometry.empty());
  EXPECT_GT(live.merged, 0u);
  for (const std::string& name : test_support::hallSequences())
    EXPECT_TRUE(fs::exists(system::trackingRecordPath(dir, name))) << name;

  system::SystemParams replay = params("");
  replay.clock.tracking_replay_dir = dir;
  expectSameRun(live, runOnce(replay, "track_replay"));

  // The recording was made with distillation on; raw streaming replayed from it
  // is the live raw-streaming run.
  const Outcome raw_live = runOnce(params("none"), "track_raw_live");
  system::SystemParams raw_replay = params("none");
  raw_replay.clock.tracking_replay_dir = dir;
  const Outcome raw = runOnce(raw_replay, "track_raw_replay");
  expectSameRun(raw_live, raw);
  EXPECT_GT(raw.bytes.front(), live.bytes.front());  // really another variant
}

// Both folders set: the robots whose recording fits are replayed, the one whose
// tracking changed (corrupted here) is tracked and recorded into the other
// folder; the run is the live run.
TEST(TrackingReplay, OneRobotTrackedAgainTheOthersReplayed) {
  const std::string clean = ::testing::TempDir() + "/hermes_tracking_mixed_clean";
  const std::string again = ::testing::TempDir() + "/hermes_tracking_mixed_again";
  fs::remove_all(clean);
  fs::remove_all(again);
  const std::vector<std::size_t> frames = {60, 60, 60};
  system::SystemParams record = params("");
  record.clock.tracking_record_dir = clean;
  ASSERT_FALSE(runOnce(record, "track_mixed_rec", frames).odometry.empty());

  system::SystemParams corrupt = params("");
  corrupt.corrupt.agent = test_support::hallSequences()[1];
  corrupt.corrupt.kind = "drift";
  corrupt.corrupt.at_s = 1;
  const Outcome live = runOnce(corrupt, "track_mixed_live", frames);
  system::SystemParams mixed = corrupt;
  mixed.clock.tracking_replay_dir = clean;
  mixed.clock.tracking_record_dir = again;
  const std::vector<std::string>& names = test_support::hallSequences();
  auto mode = [&](const system::SystemParams& p, const std::string& name) {
    auto ds = Dataset::open(test_support::renderedHall() + "/" + name, p.run.dataset);
    EXPECT_TRUE(ds.ok()) << ds.error();
    return ds.ok() ? system::trackingMode(p, name, **ds, 60) : system::TrackingMode::kLive;
  };
  EXPECT_EQ(mode(mixed, names[0]), system::TrackingMode::kReplay);
  EXPECT_EQ(mode(mixed, names[1]), system::TrackingMode::kRecord);
  EXPECT_EQ(mode(corrupt, names[0]), system::TrackingMode::kLive);
  expectSameRun(live, runOnce(mixed, "track_mixed", frames));
  EXPECT_FALSE(fs::exists(system::trackingRecordPath(again, names[0])));
  EXPECT_TRUE(fs::exists(system::trackingRecordPath(again, names[1])));
  EXPECT_FALSE(fs::exists(system::trackingRecordPath(again, names[2])));
}

TEST(TrackingReplay, StaleOrDamagedRecordingsAreRefused) {
  const std::string dir = ::testing::TempDir() + "/hermes_tracking_stale";
  fs::remove_all(dir);
  system::SystemParams record = params("");
  record.clock.tracking_record_dir = dir;
  {
    auto run = test_support::makeHallRun(record, "track_stale_rec", {40, 40, 40});
    ASSERT_TRUE(run);
    ASSERT_TRUE(run->run());
  }
  auto refusal = [&](system::SystemParams p, const std::vector<std::size_t>& frames) -> std::string {
    p.clock.tracking_replay_dir = dir;
    std::vector<system::AgentSource> sources;
    const std::string hall = test_support::renderedHall();
    for (std::size_t i = 0; i < test_support::hallSequences().size(); ++i) {
      const std::string& s = test_support::hallSequences()[i];
      auto ds = Dataset::open(hall + "/" + s, p.run.dataset);
      if (!ds) return "dataset: " + ds.error();
      sources.push_back({s, std::move(*ds), frames[i]});
    }
    auto run = system::OfflineRun::create(p, std::move(sources), ::testing::TempDir() + "/track_stale_spool",
                                          HERMES_SOURCE_DIR);
    return run.ok() ? std::string() : run.error();
  };
  EXPECT_EQ(refusal(params("none"), {40, 40, 40}), "");  // same tracking: accepted
  const std::string frames = refusal(params(""), {41, 40, 40});
  EXPECT_NE(frames.find("'frames' differs"), std::string::npos) << frames;
  system::SystemParams tracker = params("");
  tracker.run.agent.tracker.min_tracked += 1;
  const std::string changed = refusal(tracker, {40, 40, 40});
  EXPECT_NE(changed.find("'tracker_params' differs"), std::string::npos) << changed;
  system::SystemParams corrupt = params("");
  corrupt.corrupt.agent = test_support::hallSequences()[1];
  corrupt.corrupt.kind = "jump";
  const std::string corrupted = refusal(corrupt, {40, 40, 40});
  EXPECT_NE(corrupted.find("'corruption' differs"), std::string::npos) << corrupted;
  // A recording cut short (a run that did not finish) is refused as such.
  const std::string path = system::trackingRecordPath(dir, test_support::hallSequences()[0]);
  fs::resize_file(path, fs::file_size(path) - 10);
  const std::string cut = refusal(params(""), {40, 40, 40});
  EXPECT_NE(cut.find("truncated"), std::string::npos) << cut;
}
