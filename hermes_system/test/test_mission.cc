// A long mission's parts (mission.h, issue 20's soak): the plan of waves, the
// time-shifted dataset a robot flies once per sortie, and the runner flying it
// as sorties: each take-off a new session of the same robot that the server
// re-localises, live from the images or replaying the sequence's recording
// moved onto the mission clock.
#include <gtest/gtest.h>

#include <filesystem>

#include <opencv2/core.hpp>

#include "hermes/system/mission.h"
#include "hermes/system/offline_run.h"
#include "hermes/system/run_results.h"
#include "hermes/system/tracking_record.h"
#include "support/hall_run.h"
#include "support/rendered_hall.h"

using namespace hermes;
namespace fs = std::filesystem;

namespace {

constexpr double kEpoch = 1.7e9;

const AgentMetrics* metricsOf(const RunMetrics& m, const std::string& name) {
  for (const AgentMetrics& a : m.per_agent)
    if (a.agent == name) return &a;
  return nullptr;
}

/// The meeting's two robots on one mission clock: MH_01 flies once at 0 s,
/// MH_02 at 0 s and again at `second_s` (a new session). With `recordings`,
/// every sortie replays its sequence's recording there.
std::unique_ptr<system::OfflineRun> missionRun(const system::SystemParams& params, const std::string& tag,
                                               double second_s, const std::string& recordings = "",
                                               bool expect_ok = true) {
  const std::string data = test_support::renderedMeeting();
  EXPECT_FALSE(data.empty());
  const fs::path root = fs::path(::testing::TempDir()) / ("hermes_mission_" + tag);
  std::vector<system::AgentSource> sources;
  for (const std::string& seq : test_support::meetingSequences()) {
    const std::vector<double> takeoffs = seq == "MH_02_easy" ? std::vector<double>{0, second_s} : std::vector<double>{0};
    auto view = system::writeMissionView(data + "/" + seq, takeoffs, kEpoch, (root / "data" / seq).string());
    EXPECT_TRUE(view.ok()) << view.error();
    if (!view) return nullptr;
    auto ds = Dataset::open((root / "data" / seq).string(), params.run.dataset);
    auto base = Dataset::open(data + "/" + seq, params.run.dataset);
    EXPECT_TRUE(ds.ok() && base.ok());
    if (!ds || !base) return nullptr;
    system::AgentSource src{seq, std::move(*ds), 0};
    src.clock_origin = kEpoch;
    for (std::size_t s = 0; s < takeoffs.size(); ++s) {
      system::Sortie sortie;
      sortie.first_frame = view->first_frames[s];
      if (!recordings.empty()) {
        sortie.replay_path = system::trackingRecordPath(recordings, seq);
        sortie.replay_key = system::trackingKey(params, seq, **base, (*base)->size());
        sortie.replay_shift_s = view->shifts_s[s];
      }
      src.sorties.push_back(sortie);
    }
    sources.push_back(std::move(src));
  }
  auto run = system::OfflineRun::create(params, std::move(sources), (root / "spool").string(), HERMES_SOURCE_DIR);
  if (expect_ok) {
    EXPECT_TRUE(run.ok()) << run.error();
  }
  if (!run) std::printf("mission refused: %s\n", run.error().c_str());
  return run.ok() ? std::move(*run) : nullptr;
}

struct Flown {
  double ate = 1e9, victim_ate = 1e9;
  int merged = 0;
  std::int64_t bytes = 0;
};

/// Runs the mission and checks what any mission must hold: MH_02 took off
/// twice as one robot with two sessions, the second re-localised by loops;
/// every spool drained; no merge error.
Flown flyAndCheck(system::OfflineRun& run, double second_s) {
  Flown f;
  EXPECT_TRUE(run.run());
  const system::RunResults r = system::evaluateRun(run);
  std::printf("%s", system::formatReport(run, r).c_str());
  const system::OfflineAgent& victim = run.agents()[1];
  EXPECT_EQ(victim.name, "MH_02_easy");
  EXPECT_EQ(run.agents()[0].resets.size(), 0u);
  if (victim.resets.size() != 1u) {
    ADD_FAILURE() << "MH_02 took off " << victim.resets.size() << " times again";
    return f;
  }
  const system::AgentResetRecord& t = victim.resets[0];
  EXPECT_TRUE(t.takeoff);
  EXPECT_NEAR(t.at_s, second_s, 0.11);
  EXPECT_EQ(t.new_session, t.old_session + 1);
  EXPECT_EQ(victim.windows_lost_landed, 0u);
  for (const system::OfflineAgent& a : run.agents()) {
    EXPECT_TRUE(a.robot) << a.name;
    EXPECT_EQ(a.pipeline->uplink()->backlogBytes(), 0u) << a.name << ": spool not drained";
  }
  EXPECT_EQ(run.server().counters().merge_errors, 0u) << run.server().counters().last_error;
  if (!victim.robot) return f;
  const AgentStats* st = run.server().bookkeeper().stats(*victim.robot);
  EXPECT_TRUE(st && st->sessions.size() == 2u);
  if (st && st->sessions.count(t.new_session)) {
    EXPECT_TRUE(st->sessions.at(t.new_session).relocalised) << "the second sortie was not re-localised";
  }
  const AgentMetrics* m = metricsOf(r.metrics, victim.name);
  EXPECT_TRUE(m && m->merged_ate_rmse_m && m->matched_poses && r.metrics.ate_rmse_m);
  if (!m || !m->merged_ate_rmse_m || !r.metrics.ate_rmse_m || !st) return f;
  // Both sorties' keyframes in its merged trajectory, against the mission's ground truth.
  EXPECT_GT(static_cast<std::uint64_t>(*m->matched_poses),
            st->sessions.at(t.old_session).keyframes + st->sessions.at(t.new_session).keyframes / 2);
  f.ate = *r.metrics.ate_rmse_m;
  f.victim_ate = *m->merged_ate_rmse_m;
  f.merged = r.metrics.agents_merged.value_or(0);
  f.bytes = r.metrics.bytes_total.value_or(0);
  std::printf("mission: merged ATE all %.2f cm, MH_02 (two sorties) %.2f cm, %lld bytes\n", f.ate * 100,
              f.victim_ate * 100, static_cast<long long>(f.bytes));
  return f;
}

}  // namespace

TEST(Mission, WavesStaggerTheRobotsAndEveryRobotLandsBeforeItsNextTakeOff) {
  system::MissionPlan plan;
  plan.robots = 3;
  plan.duration_s = 100;
  plan.waves = 2;
  plan.sorties = 2;
  plan.stagger_s = 5;
  plan.sequences = {"A", "B"};
  auto robots = system::planMission(plan, [](const std::string& s) { return s == "A" ? 10.0 : 20.0; });
  ASSERT_TRUE(robots.ok()) << robots.error();
  ASSERT_EQ(robots->size(), 3u);
  EXPECT_EQ((*robots)[0].name, "r01");
  EXPECT_EQ((*robots)[2].sequence, "A");
  EXPECT_EQ((*robots)[1].sequence, "B");
  EXPECT_EQ((*robots)[2].takeoffs_s, (std::vector<double>{10, 60}));
  plan.duration_s = 40;  // B's 20-s sortie from 5 s has not landed (+2 s) at 25 s
  auto tight = system::planMission(plan, [](const std::string& s) { return s == "A" ? 10.0 : 20.0; });
  ASSERT_FALSE(tight.ok());
  EXPECT_NE(tight.error().find("r02"), std::string::npos) << tight.error();
  plan.duration_s = 90;  // one sortie each: robot k in wave k mod 3, in order within the wave
  plan.waves = 3;
  plan.sorties = 1;
  plan.robots = 4;
  auto spread = system::planMission(plan, [](const std::string&) { return 10.0; });
  ASSERT_TRUE(spread.ok()) << spread.error();
  EXPECT_EQ((*spread)[0].takeoffs_s, (std::vector<double>{0}));
  EXPECT_EQ((*spread)[2].takeoffs_s, (std::vector<double>{60}));
  EXPECT_EQ((*spread)[3].takeoffs_s, (std::vector<double>{5}));
  plan.sorties = 4;  // more sorties than waves
  EXPECT_FALSE(system::planMission(plan, [](const std::string&) { return 1.0; }).ok());
  plan.sorties = 1;
  plan.sequences.clear();
  EXPECT_FALSE(system::planMission(plan, [](const std::string&) { return 1.0; }).ok());
}

TEST(Mission, TheViewHoldsTheSequenceOncePerSortieOnTheMissionClock) {
  const std::string data = test_support::renderedMeeting();
  ASSERT_FALSE(data.empty());
  const std::string seq = data + "/" + test_support::meetingSequences()[0];
  const std::string out = ::testing::TempDir() + "/hermes_mission_view";
  auto view = system::writeMissionView(seq, {5, 100}, kEpoch, out);
  ASSERT_TRUE(view.ok()) << view.error();
  auto base = Dataset::open(seq);
  auto ds = Dataset::open(out);
  ASSERT_TRUE(base.ok() && ds.ok());
  const std::size_t n = (*base)->size();
  EXPECT_EQ(view->frames, 2 * n);
  EXPECT_EQ(view->first_frames, (std::vector<std::size_t>{0, n}));
  ASSERT_EQ((*ds)->size(), 2 * n);
  EXPECT_NEAR((*ds)->frameTime(0), kEpoch + 5, 1e-6);
  EXPECT_NEAR((*ds)->frameTime(n), kEpoch + 100, 1e-6);
  EXPECT_NEAR((*ds)->frameTime(n + 7) - (*ds)->frameTime(n), (*base)->frameTime(7) - (*base)->frameTime(0), 1e-6);
  EXPECT_NEAR((*ds)->frameTime(n + 7) - view->shifts_s[1], (*base)->frameTime(7), 1e-6);
  // The images are the sequence's; the ground truth follows the shifted clock.
  auto a = (*base)->loadStereo(7);
  auto b = (*ds)->loadStereo(n + 7);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(cv::norm(a->left, b->left, cv::NORM_L1), 0.0);
  const Trajectory& gt = (*ds)->info().groundtruth;
  const Trajectory& gt0 = (*base)->info().groundtruth;
  ASSERT_EQ(gt.size(), 2 * gt0.size());
  EXPECT_NEAR(gt[gt0.size()].t - view->shifts_s[1], gt0[0].t, 1e-6);
  EXPECT_LT((gt[gt0.size() + 3].T_W_B.translation() - gt0[3].T_W_B.translation()).norm(), 1e-9);
  // Bad input is named.
  EXPECT_FALSE(system::writeMissionView(data + "/nothing", {0}, kEpoch, out + "_x").ok());
  EXPECT_FALSE(system::writeMissionView(seq, {}, kEpoch, out + "_y").ok());
}

TEST(Mission, ASecondSortieIsANewSessionTheServerReLocalisesLiveAndReplayed) {
  system::SystemParams params = test_support::testRunParams();
  params.run.agent.distill.milp_time_limit_s = 60;  // no wall-clock limit that binds
  params.run.agent.distill.trim_time_limit_s = 60;
  // Live: both sorties tracked from the images; the server's health sampled.
  system::SystemParams sampled = params;
  sampled.clock.health_period_s = 5;
  auto live = missionRun(sampled, "live", 40);
  ASSERT_TRUE(live);
  const Flown l = flyAndCheck(*live, 40);
  EXPECT_EQ(l.merged, 2);
  EXPECT_LT(l.victim_ate, 0.08);
  EXPECT_LT(l.ate, 0.08);
  // Every 5 s and at the end: two robots flying, then one (MH_01 landed at
  // 30 s), none between MH_02's sorties; the map and its state only grow.
  const std::vector<system::HealthSample>& h = live->health();
  ASSERT_GE(h.size(), 14u);
  EXPECT_EQ(h[1].flying, 2);
  for (const system::HealthSample& x : h)
    if (x.time_s > 31 && x.time_s < 39) {
      EXPECT_EQ(x.flying, 0) << x.time_s;
    }
  EXPECT_EQ(h.back().keyframes, live->server().map().keyframeCount());
  EXPECT_EQ(h.back().state_bytes, live->server().saveState().size());
  EXPECT_GT(h.back().rss_bytes, 0u);
  std::size_t processed = 0;
  for (std::size_t i = 1; i < h.size(); ++i) {
    EXPECT_GE(h[i].keyframes, h[i - 1].keyframes);
    processed += h[i].submaps;
  }
  EXPECT_EQ(processed + h[0].submaps, live->server().timings().count("submap"));
  live.reset();
  // The sequences' tracking recorded once (a plain run), then every sortie replays it.
  const std::string rec = ::testing::TempDir() + "/hermes_mission_recordings";
  fs::remove_all(rec);
  system::SystemParams record = params;
  record.clock.tracking_record_dir = rec;
  auto plain = test_support::makeMeetingRun(record, "mission_record");
  ASSERT_TRUE(plain);
  ASSERT_TRUE(plain->run());
  plain.reset();
  auto replayed = missionRun(params, "replay", 40, rec);
  ASSERT_TRUE(replayed);
  for (const system::OfflineAgent& a : replayed->agents()) EXPECT_TRUE(a.pipeline->replaying()) << a.name;
  const Flown r = flyAndCheck(*replayed, 40);
  EXPECT_EQ(r.merged, 2);
  // The recording is the same tracking on another clock: the same mission
  // within the shift's rounding of the stamps (1e-7 s).
  EXPECT_NEAR(r.victim_ate, l.victim_ate, 0.2 * l.victim_ate + 0.003);
  EXPECT_NEAR(static_cast<double>(r.bytes), static_cast<double>(l.bytes), 0.05 * l.bytes);
  // A recording that is not the sortie's sequence is refused by name.
  system::SystemParams p2 = params;
  auto wrong = missionRun(p2, "wrong", 40, rec + "_none", /*expect_ok=*/false);
  EXPECT_FALSE(wrong) << "a missing recording was accepted";
}
