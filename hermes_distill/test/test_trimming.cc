// Keyframe trimming (Eq. 15-16): optimality against brute force, first/last
// kept, N_KF respected, connectivity, and the submap surgery around it.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>
#include <unordered_set>

#include "distill_fixture.h"
#include "hermes/distill/keyframe_trimming.h"

namespace hermes {
namespace distill {
namespace {

bool connected(const Submap& w, const std::vector<int>& kept, int min_shared) {
  for (std::size_t k = 1; k < kept.size(); ++k) {
    const bool adjacent = kept[k] == kept[k - 1] + 1;
    if (!adjacent && sharedLandmarks(w, static_cast<std::size_t>(kept[k - 1]), static_cast<std::size_t>(kept[k])) < min_shared)
      return false;
  }
  return true;
}

TEST(Trimming, KeepsEndsRespectsBudgetAndStaysConnected) {
  DistillParams params;
  for (const std::string seq : {"MH_01_easy", "V1_01_easy"}) {
    for (double t : {20.0, 70.0}) {
      const Submap w = testing::window(seq, t).submap;
      const int n = static_cast<int>(w.keyframes.size());
      ASSERT_GE(n, 10);
      for (int N = 2; N <= n; ++N) {
        const TrimResult r = trimKeyframes(w, N, params);
        ASSERT_FALSE(r.kept.empty());
        EXPECT_EQ(r.kept.front(), 0);
        EXPECT_EQ(r.kept.back(), n - 1);
        EXPECT_TRUE(connected(w, r.kept, params.trim_min_shared)) << seq << " N=" << N;
        if (r.status != SolveStatus::kInfeasibleRelaxed) {
          EXPECT_LE(static_cast<int>(r.kept.size()), N);
        }
        EXPECT_TRUE(std::is_sorted(r.kept.begin(), r.kept.end()));
      }
    }
  }
}

TEST(Trimming, MilpMatchesBruteForce) {
  DistillParams params;
  params.trim_time_limit_s = 5.0;
  params.trim_lambda = 0.01;
  for (double t : {15.0, 55.0, 95.0}) {
    const Submap w = testing::window("MH_01_easy", t).submap;
    const int n = static_cast<int>(w.keyframes.size());
    for (int N : {3, 5, 7}) {
      double best = -std::numeric_limits<double>::infinity();
      for (std::uint32_t mask = 0; mask < (1u << (n - 2)); ++mask) {
        std::vector<int> kept = {0};
        for (int j = 1; j < n - 1; ++j)
          if (mask & (1u << (j - 1))) kept.push_back(j);
        kept.push_back(n - 1);
        if (static_cast<int>(kept.size()) > N || !connected(w, kept, params.trim_min_shared)) continue;
        best = std::max(best, trimObjective(w, kept, params));
      }
      const TrimResult r = trimKeyframes(w, N, params);
      EXPECT_EQ(r.status, SolveStatus::kOptimal);
      EXPECT_NEAR(r.objective, best, 1e-6) << "t=" << t << " N=" << N;
    }
  }
}

TEST(Trimming, ExhaustedBudgetReturnsTheImprovedPath) {
  DistillParams params;
  const Submap w = testing::window("V1_01_easy", 70.0).submap;
  const int n = static_cast<int>(w.keyframes.size());
  const int N = std::max(3, n / 2);
  DistillParams no_time = params;
  no_time.trim_time_limit_s = 1e-9;  // the deadline passes before the root LP
  const TrimResult fast = trimKeyframes(w, N, no_time);
  EXPECT_EQ(fast.status, SolveStatus::kGreedyFallback);
  ASSERT_FALSE(fast.kept.empty());
  EXPECT_EQ(fast.kept.front(), 0);
  EXPECT_EQ(fast.kept.back(), n - 1);
  EXPECT_LE(static_cast<int>(fast.kept.size()), N);
  EXPECT_TRUE(connected(w, fast.kept, params.trim_min_shared));
  params.trim_time_limit_s = 5.0;
  const TrimResult exact = trimKeyframes(w, N, params);
  EXPECT_EQ(exact.status, SolveStatus::kOptimal);
  EXPECT_GE(exact.objective, fast.objective - 1e-9);
}

TEST(Trimming, WorkLimitsIgnoreTheClockAndRepeatExactly) {
  DistillParams params;
  params.solver_limits = "work";
  params.trim_time_limit_s = 1e-9;  // not read under work limits
  const Submap w = testing::window("V1_01_easy", 70.0).submap;
  const int n = static_cast<int>(w.keyframes.size());
  const int N = std::max(3, n / 2);
  DistillParams exact_time;
  exact_time.trim_time_limit_s = 5.0;
  const TrimResult exact = trimKeyframes(w, N, exact_time);
  ASSERT_EQ(exact.status, SolveStatus::kOptimal);
  params.trim_max_nodes = 1000000;
  params.trim_max_lp_iterations = 1000000;
  const TrimResult ample = trimKeyframes(w, N, params);
  EXPECT_EQ(ample.status, SolveStatus::kOptimal);
  EXPECT_NEAR(ample.objective, exact.objective, 1e-9);
  // Small limits: the same kept set on every call, a connected chain within N.
  for (const auto& [nodes, iterations] : {std::pair{1, 1000000}, std::pair{1000000, 1}}) {
    params.trim_max_nodes = nodes;
    params.trim_max_lp_iterations = iterations;
    const TrimResult r = trimKeyframes(w, N, params);
    EXPECT_NE(r.status, SolveStatus::kTimeLimited);
    if (iterations == 1) {
      EXPECT_EQ(r.status, SolveStatus::kGreedyFallback);  // root LP stopped
    }
    EXPECT_LE(static_cast<int>(r.kept.size()), N);
    EXPECT_TRUE(connected(w, r.kept, params.trim_min_shared));
    EXPECT_LE(r.objective, exact.objective + 1e-9);
    for (int rep = 0; rep < 3; ++rep) EXPECT_EQ(trimKeyframes(w, N, params).kept, r.kept);
  }
}

TEST(Trimming, UnreachableBudgetKeepsTheShortestConnectedChain) {
  DistillParams params;
  params.trim_min_shared = 1000000;  // only tracker-adjacent keyframes connect
  const Submap w = testing::window("V1_01_easy", 40.0).submap;
  const TrimResult r = trimKeyframes(w, 3, params);
  EXPECT_EQ(r.status, SolveStatus::kInfeasibleRelaxed);
  EXPECT_EQ(r.kept.size(), w.keyframes.size());
}

TEST(Trimming, SeparationIsTheDistanceToTheNearestOtherKeyframe) {
  Submap w;
  w.cameras.push_back(eurocCam0Intrinsics());
  for (int k = 0; k < 3; ++k) {
    Keyframe kf;
    kf.id = static_cast<KeyframeId>(k + 1);
    kf.T_A_C = SE3(Mat3::Identity(), Vec3(k == 2 ? 3.0 : k * 1.0, 0, 0));
    w.keyframes.push_back(kf);
  }
  DistillParams params;
  params.trim_w_trans = 2.0;
  const auto s = keyframeSeparation(w, params);
  EXPECT_NEAR(s[0], 2.0, 1e-12);
  EXPECT_NEAR(s[1], 2.0, 1e-12);
  EXPECT_NEAR(s[2], 4.0, 1e-12);
}

TEST(Trimming, SurplusCapGrowsWithTheWindowsMotionOrItsTrackedKeyframesWithinItsBounds) {
  // 20 keyframes 0.25 m apart, turning 0.05 rad about z each step.
  auto window = [](double step_m) {
    Submap w;
    w.cameras.push_back(eurocCam0Intrinsics());
    for (int k = 0; k < 20; ++k) {
      Keyframe kf;
      kf.id = static_cast<KeyframeId>(k + 1);
      kf.T_A_C = SE3(Eigen::AngleAxisd(0.05 * k, Vec3::UnitZ()).toRotationMatrix(), Vec3(step_m * k, 0, 0));
      w.keyframes.push_back(kf);
    }
    return w;
  };
  DistillParams params;  // w_trans 2 / m, w_rot 5.73 / rad
  const double motion = 19 * (params.trim_w_trans * 0.25 + params.trim_w_rot * 0.05);
  EXPECT_NEAR(windowMotion(window(0.25), params), motion, 1e-9);
  params.tracked_keyframe_fraction = 0;  // the motion rule alone first
  params.motion_keyframe_spacing = 0;    // off
  EXPECT_EQ(surplusKeyframeCap(window(0.25), params), params.max_keyframes);
  params.motion_keyframe_spacing = 1.0;
  EXPECT_EQ(surplusKeyframeCap(window(0.25), params), static_cast<int>(std::ceil(motion)));  // 15
  EXPECT_EQ(surplusKeyframeCap(window(0.0), params), params.max_keyframes);  // turning only: 6 -> floor
  EXPECT_EQ(surplusKeyframeCap(window(1.0), params), params.trouble_max_keyframes);  // 44 -> ceiling

  // A view that changes fast for little motion (the tracker made 20 keyframes
  // while the camera hardly moved): the tracked fraction sets the cap.
  params.tracked_keyframe_fraction = 0.7;
  EXPECT_EQ(surplusKeyframeCap(window(0.0), params), 14);                           // ceil(0.7 x 20)
  EXPECT_EQ(surplusKeyframeCap(window(0.25), params), static_cast<int>(std::ceil(motion)));  // motion wins: 15
  params.motion_keyframe_spacing = 0;
  EXPECT_EQ(surplusKeyframeCap(window(0.25), params), 14);  // the fraction alone
  params.tracked_keyframe_fraction = 0.5;
  EXPECT_EQ(surplusKeyframeCap(window(0.0), params), params.max_keyframes);  // 10 -> floor
  params.tracked_keyframe_fraction = 1.0;
  EXPECT_EQ(surplusKeyframeCap(window(0.0), params), 20);
  params.trouble_max_keyframes = 16;
  EXPECT_EQ(surplusKeyframeCap(window(0.0), params), 16);  // -> ceiling
  params.tracked_keyframe_fraction = 1.5;
  EXPECT_FALSE(params.validate().ok());
  params.tracked_keyframe_fraction = -0.1;
  EXPECT_FALSE(params.validate().ok());
}

TEST(Trimming, AppliedTrimDropsOrphansAndAddsOdometry) {
  DistillParams params;
  const Submap w = testing::window("MH_01_easy", 100.0).submap;
  const TrimResult r = trimKeyframes(w, 4, params);
  const Submap t = applyKeyframeTrim(w, r.kept);
  EXPECT_EQ(t.validate(), "");
  ASSERT_EQ(t.keyframes.size(), r.kept.size());
  std::unordered_set<KeyframeId> kept;
  for (const auto& kf : t.keyframes) kept.insert(kf.id);
  std::unordered_set<LandmarkId> in_trim;
  for (const auto& lm : t.landmarks) {
    EXPECT_FALSE(lm.observations.empty());
    in_trim.insert(lm.id);
  }
  for (const auto& lm : w.landmarks) {
    bool seen = false;
    for (const auto& ob : lm.observations) seen = seen || kept.count(ob.keyframe);
    EXPECT_EQ(seen, in_trim.count(lm.id) == 1);
  }
  ASSERT_EQ(t.odometry.size(), t.keyframes.size() - 1);
  for (std::size_t k = 0; k < t.odometry.size(); ++k) {
    const OdometryEdge& e = t.odometry[k];
    EXPECT_EQ(e.from, t.keyframes[k].id);
    EXPECT_EQ(e.to, t.keyframes[k + 1].id);
    const SE3 T_A_to = t.keyframes[k].T_A_C * e.T_from_to;
    EXPECT_LT((T_A_to.translation() - t.keyframes[k + 1].T_A_C.translation()).norm(), 1e-9);
    EXPECT_GT(e.information(0, 0), 0.0);
    // Across dropped keyframes the edge is no more certain than the window's
    // odometry between them: composed variances add up.
    const auto first = std::find_if(w.odometry.begin(), w.odometry.end(),
                                    [&](const OdometryEdge& o) { return o.from == e.from; });
    ASSERT_NE(first, w.odometry.end());
    if (first->to != e.to) EXPECT_LT(e.information(0, 0), first->information(0, 0));
    else EXPECT_TRUE(e.information.isApprox(first->information));
  }
  // A loss before a dropped keyframe moves to the next kept one.
  Submap lossy = w;
  std::size_t dropped = 0;
  while (dropped < w.keyframes.size() &&
         std::find(r.kept.begin(), r.kept.end(), static_cast<int>(dropped)) != r.kept.end())
    ++dropped;
  ASSERT_LT(dropped, w.keyframes.size());
  lossy.keyframes[dropped].lost_before = true;
  const Submap lt = applyKeyframeTrim(lossy, r.kept);
  int flagged = 0;
  for (const Keyframe& kf : lt.keyframes) {
    flagged += kf.lost_before;
    if (kf.lost_before) {
      EXPECT_GT(kf.id, lossy.keyframes[dropped].id);
    }
  }
  EXPECT_EQ(flagged, 1);
  // Without the window's edges between two kept keyframes no edge is invented.
  Submap no_edges = w;
  no_edges.odometry.clear();
  EXPECT_TRUE(applyKeyframeTrim(no_edges, r.kept).odometry.empty());
}

TEST(Trimming, KeepLandmarksReindexesKeypoints) {
  const Submap w = testing::window("V1_01_easy", 60.0).submap;
  std::vector<int> keep;
  for (int i = 0; i < static_cast<int>(w.landmarks.size()); i += 3) keep.push_back(i);
  const Submap s = keepLandmarks(w, keep, 0);
  EXPECT_EQ(s.validate(), "");
  EXPECT_EQ(s.landmarks.size(), keep.size());
  std::size_t keypoints = 0;
  for (const auto& kf : s.keyframes) keypoints += kf.keypoints.size();
  EXPECT_EQ(keypoints, s.observationCount());
  for (const auto& lm : s.landmarks)
    for (const auto& ob : lm.observations) {
      const Keyframe* kf = nullptr;
      for (const auto& k : s.keyframes) if (k.id == ob.keyframe) kf = &k;
      ASSERT_NE(kf, nullptr);
      EXPECT_EQ(kf->keypoint_landmark[ob.keypoint], lm.id);
    }
  const Submap raw = keepLandmarks(w, keep, kAllKeypoints);
  EXPECT_EQ(raw.validate(), "");
  EXPECT_EQ(raw.keyframes[0].keypoints.size(), w.keyframes[0].keypoints.size());

  // Loop keypoints: up to 20 more per keyframe, unlinked, measured depths first.
  const Submap extra = keepLandmarks(w, keep, 20);
  EXPECT_EQ(extra.validate(), "");
  EXPECT_EQ(extra.observationCount(), s.observationCount());
  for (std::size_t k = 0; k < extra.keyframes.size(); ++k) {
    const Keyframe& in = w.keyframes[k];
    std::size_t free_with_depth = 0;
    for (std::size_t p = 0; p < in.keypoints.size(); ++p)
      free_with_depth += in.keypoints[p].depth > 0 ? 1 : 0;
    free_with_depth -= std::min(free_with_depth, s.keyframes[k].keypoints.size());
    const Keyframe& out = extra.keyframes[k];
    const std::size_t added = out.keypoints.size() - s.keyframes[k].keypoints.size();
    EXPECT_EQ(added, std::min<std::size_t>(20, in.keypoints.size() - s.keyframes[k].keypoints.size()));
    std::size_t unlinked = 0, unlinked_with_depth = 0;
    for (std::size_t p = 0; p < out.keypoints.size(); ++p) {
      if (out.keypoint_landmark[p] != kInvalidId) continue;
      ++unlinked;
      unlinked_with_depth += out.keypoints[p].depth > 0 ? 1 : 0;
    }
    EXPECT_EQ(unlinked, added);
    if (free_with_depth >= 40) {
      EXPECT_EQ(unlinked_with_depth, added) << "keyframe " << k;
    }
  }
  // Half the depths unknown: the extra keypoints are still those with depths.
  Submap half = w;
  for (Keyframe& kf : half.keyframes)
    for (std::size_t p = 0; p < kf.keypoints.size(); p += 2) kf.keypoints[p].depth = 0;
  const Submap picked = keepLandmarks(half, keep, 20);
  std::size_t extra_total = 0, extra_with_depth = 0;
  for (const Keyframe& kf : picked.keyframes)
    for (std::size_t p = 0; p < kf.keypoints.size(); ++p)
      if (kf.keypoint_landmark[p] == kInvalidId) {
        ++extra_total;
        extra_with_depth += kf.keypoints[p].depth > 0 ? 1 : 0;
      }
  EXPECT_GT(extra_total, 0u);
  EXPECT_EQ(extra_with_depth, extra_total);
}

}  // namespace
}  // namespace distill
}  // namespace hermes
