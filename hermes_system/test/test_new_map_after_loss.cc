// A robot whose camera goes dark for 2 s (black frames, then the scene again, the
// robot having moved on): tracking is lost, relocalisation cannot work, and after
// tracker.reinit_after_s the agent starts a new map in a new session at once. It
// tracks again as soon as the images can be tracked, both sessions reach the
// server, and the server ties the new one by loops when the robot's path meets the
// global map, or reports it apart when it never does.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "hermes/core/euroc_dataset.h"
#include "hermes/system/offline_run.h"
#include "hermes/system/run_results.h"
#include "support/hall_run.h"
#include "support/rendered_hall.h"

using namespace hermes;
namespace fs = std::filesystem;

namespace {

/// A copy of the rendered folders `dir`/<seq> (symlinks) in which `victim`'s stereo
/// images stamped in [from_s, to_s) after its first frame are black. Returns the
/// copy's root and sets *dark_end to the stamp of the first frame after the stretch.
std::string darkenedCopy(const std::string& dir, const std::vector<std::string>& seqs,
                         const std::string& victim, double from_s, double to_s, const std::string& tag,
                         double* dark_end) {
  const fs::path root = fs::path(::testing::TempDir()) / ("hermes_dark_" + tag);
  fs::remove_all(root);
  for (const std::string& s : seqs) {
    if (s != victim) {
      fs::create_directories(root);
      fs::create_directory_symlink(fs::path(dir) / s, root / s);
      continue;
    }
    const fs::path src = fs::path(dir) / s / "mav0", dst = root / s / "mav0";
    for (const auto& e : fs::recursive_directory_iterator(src)) {
      const fs::path rel = fs::relative(e.path(), src);
      if (e.is_directory()) {
        fs::create_directories(dst / rel);
        continue;
      }
      fs::create_directories((dst / rel).parent_path());
      fs::create_symlink(e.path(), dst / rel);
    }
    auto ds = EurocDataset::open((root / s).string());
    EXPECT_TRUE(ds.ok()) << ds.error();
    if (!ds.ok()) return "";
    const double t0 = nsToSeconds(ds->pairs().front().stamp_ns);
    *dark_end = -1;
    for (const auto& p : ds->pairs()) {
      const double t = nsToSeconds(p.stamp_ns) - t0;
      if (t >= to_s && *dark_end < 0) *dark_end = nsToSeconds(p.stamp_ns);
      if (t < from_s || t >= to_s) continue;
      for (const std::string& path : {p.left_path, p.right_path}) {
        fs::remove(path);
        cv::imwrite(path, cv::Mat(ds->cam0().K.height, ds->cam0().K.width, CV_8UC1, cv::Scalar(0)));
      }
    }
  }
  return root.string();
}

const system::OfflineAgent* agentNamed(const system::OfflineRun& run, const std::string& name) {
  for (const system::OfflineAgent& a : run.agents())
    if (a.name == name) return &a;
  return nullptr;
}

/// Seconds from the end of the dark stretch to the robot's next tracked pose.
double secondsToTrackAgain(const system::OfflineAgent& a, double dark_end) {
  for (const StampedPose& p : a.pipeline->trajectory())
    if (p.t >= dark_end - 1e-9) return p.t - dark_end;
  return 1e9;
}

}  // namespace

TEST(NewMapAfterLoss, DarkStretchStartsANewSessionThatLoopsTie) {
  // The two meeting robots fly the same route for 30 s; MH_02 is dark from 12 to 14 s.
  system::SystemParams params = test_support::testRunParams();
  const std::string victim = "MH_02_easy";
  double dark_end = 0;
  const std::string dir = darkenedCopy(test_support::renderedMeeting(), test_support::meetingSequences(),
                                       victim, 12.0, 14.0, "meeting", &dark_end);
  ASSERT_FALSE(dir.empty());
  auto run = test_support::makeRunOn(params, dir, test_support::meetingSequences(), "dark_meeting");
  ASSERT_TRUE(run);
  ASSERT_TRUE(run->run());
  const system::RunResults r = system::evaluateRun(*run);
  std::printf("%s", system::formatReport(*run, r).c_str());

  const system::OfflineAgent* a = agentNamed(*run, victim);
  ASSERT_TRUE(a && a->robot);
  EXPECT_EQ(a->pipeline->newMaps(), 1);
  EXPECT_TRUE(a->resets.empty()) << "the agent itself started the new map, not the runner";
  const double again = secondsToTrackAgain(*a, dark_end);
  std::printf("tracking again %.2f s after the images came back\n", again);
  EXPECT_LE(again, 1.0);

  const AgentStats* st = run->server().bookkeeper().stats(*a->robot);
  ASSERT_TRUE(st);
  ASSERT_EQ(st->sessions.size(), 2u) << "both sessions reached the server";
  const SessionStats& fresh = st->sessions.at(a->pipeline->session());
  EXPECT_EQ(fresh.anchored_by, SessionAnchor::kLoop);
  EXPECT_TRUE(fresh.relocalised);
  EXPECT_FALSE(fresh.reported_new);
  EXPECT_EQ(r.metrics.agents_merged.value_or(0), 2);
  EXPECT_EQ(run->server().counters().merge_errors, 0u) << run->server().counters().last_error;
  for (const AgentMetrics& m : r.metrics.per_agent)
    if (m.agent == victim) {
      EXPECT_EQ(m.new_maps.value_or(0), 1);
      ASSERT_TRUE(m.merged_ate_rmse_m);
      std::printf("merged ATE of %s over both sessions: %.2f cm\n", victim.c_str(), *m.merged_ate_rmse_m * 100);
      EXPECT_LT(*m.merged_ate_rmse_m, 0.10);
    }
}

// The same dark stretch on the other robot, MH_01, whose path after it runs
// through what MH_02 mapped: the server's downlink has sent MH_01 the map
// around it (borrowed map), so its new session is placed in the world at its
// first keyframe, before any loop; without the downlink its own idea of where
// it is stays off by its motion in the dark until the server re-localises it.
TEST(NewMapAfterLoss, TheBorrowedMapPlacesTheNewSessionAtOnce) {
  const std::string victim = "MH_01_easy";
  double dark_end = 0;
  const std::string dir = darkenedCopy(test_support::renderedMeeting(), test_support::meetingSequences(),
                                       victim, 12.0, 14.0, "meeting_borrowed", &dark_end);
  ASSERT_FALSE(dir.empty());
  struct Outcome {
    agent::AgentPipeline::SessionPlacement fresh;
    agent::AgentPipeline::BorrowedStats borrowed;
    double global_rmse_m = 1e9;
    std::int64_t down_bytes = 0;
    double seconds = 0;
  };
  auto fly = [&](bool downlink) {
    Outcome o;
    system::SystemParams params = test_support::testRunParams();
    params.server.downlink.enabled = downlink;
    auto run = test_support::makeRunOn(params, dir, test_support::meetingSequences(),
                                       downlink ? "borrowed_on" : "borrowed_off");
    EXPECT_TRUE(run);
    if (!run) return o;
    EXPECT_TRUE(run->run());
    const system::RunResults r = system::evaluateRun(*run);
    std::printf("%s", system::formatReport(*run, r).c_str());
    const system::OfflineAgent* a = agentNamed(*run, victim);
    EXPECT_TRUE(a);
    if (!a) return o;
    EXPECT_EQ(a->pipeline->newMaps(), 1);
    const auto placements = a->pipeline->placements();
    EXPECT_EQ(placements.size(), 2u);
    if (!placements.empty()) o.fresh = placements.back();
    o.borrowed = a->pipeline->borrowedStats();
    o.seconds = run->simTime();
    for (const AgentMetrics& m : r.metrics.per_agent)
      if (m.agent == victim) {
        o.global_rmse_m = m.global_pose_rmse_m.value_or(1e9);
        o.down_bytes = m.downlink_bytes.value_or(0);
      }
    return o;
  };
  const Outcome with = fly(true), without = fly(false);
  const auto placedAfter = [](const Outcome& o) {
    return o.fresh.placed < 0 ? 1e9 : o.fresh.placed - o.fresh.started;
  };
  std::printf("new session placed %.2f s after it began with the downlink (%s), %.2f s without;\n"
              "own global pose %.1f cm RMSE with, %.1f cm without; borrowed: %zu landmarks, %zu kB held, "
              "%lld attempt(s); downlink %.1f kB\n",
              placedAfter(with), with.fresh.by_borrowed ? "borrowed map" : "server", placedAfter(without),
              with.global_rmse_m * 100, without.global_rmse_m * 100, with.borrowed.landmarks,
              with.borrowed.memory_bytes / 1000, (long long)with.borrowed.attempts, with.down_bytes / 1e3);
  EXPECT_TRUE(with.fresh.by_borrowed);
  EXPECT_EQ(with.borrowed.relocalisations, 1);
  EXPECT_LE(placedAfter(with), 1.5);
  EXPECT_FALSE(without.fresh.by_borrowed);
  EXPECT_GT(placedAfter(without), placedAfter(with) + 1.0);
  EXPECT_LT(with.global_rmse_m, 0.05);
  EXPECT_LT(with.global_rmse_m, 0.5 * without.global_rmse_m);
  EXPECT_EQ(without.down_bytes, 0);
  const system::SystemParams defaults = test_support::testRunParams();
  EXPECT_LE(static_cast<double>(with.down_bytes),
            defaults.server.downlink.bytes_per_s * (with.seconds + defaults.server.downlink.burst_s));
}

TEST(NewMapAfterLoss, ANewSessionThatNeverMeetsTheMapIsReportedApart) {
  system::SystemParams params = test_support::testRunParams();
  params.run.agent.setWindowPeriod(2.5);  // windows of the new session before the end
  params.server.bookkeeper.relocalisation_timeout_s = 1.5;
  const std::string victim = test_support::hallSequences().back();
  double dark_end = 0;
  const std::string dir = darkenedCopy(test_support::renderedHall(), test_support::hallSequences(), victim,
                                       3.0, 4.5, "hall", &dark_end);
  ASSERT_FALSE(dir.empty());
  auto run = test_support::makeRunOn(params, dir, test_support::hallSequences(), "dark_hall");
  ASSERT_TRUE(run);
  // It never comes back to a mapped place: no place candidate to or from its new session.
  run->onServerCreated([](server::Server& s) {
    s.mapManager().setCandidateHook([](const KeyframeKey& q, std::vector<PlaceCandidate>* c) {
      if (q.session > 0) return c->clear();
      c->erase(std::remove_if(c->begin(), c->end(), [](const PlaceCandidate& p) { return p.key.session > 0; }),
               c->end());
    });
  });
  ASSERT_TRUE(run->run());
  const system::RunResults r = system::evaluateRun(*run);
  const system::OfflineAgent* a = agentNamed(*run, victim);
  ASSERT_TRUE(a && a->robot);
  EXPECT_EQ(a->pipeline->newMaps(), 1);
  EXPECT_LE(secondsToTrackAgain(*a, dark_end), 1.0);
  const AgentStats* st = run->server().bookkeeper().stats(*a->robot);
  ASSERT_TRUE(st);
  ASSERT_EQ(st->sessions.size(), 2u);
  const SessionStats& fresh = st->sessions.at(a->pipeline->session());
  EXPECT_EQ(fresh.anchored_by, SessionAnchor::kNone);
  EXPECT_TRUE(fresh.reported_new);
  EXPECT_EQ(r.metrics.robots_new.value_or(-1), 1);
  EXPECT_GE(r.metrics.agents_merged.value_or(0), 2);  // the others merged as usual
}
