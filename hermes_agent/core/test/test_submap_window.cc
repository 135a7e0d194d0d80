#include <gtest/gtest.h>

#include <map>
#include <set>

#include "hermes/agent/submap_window.h"
#include "hermes/agent/tracker.h"
#include "hermes/agent/window_cut.h"
#include "room_sequence.h"

using namespace hermes;

TEST(SubmapWindow, ConsecutiveWindowsAreValidAndChain) {
  TrackerParams p;
  p.window.period_s = 0.5;
  Tracker tracker(p, test::roomK(), 0.11);
  WindowCut cut(tracker, p.window);
  cut.setAgent(uuidFromSeed(4), 2);
  std::vector<Submap> windows;
  std::vector<distill::MotionHint> hints;
  auto st = test::runRoomSequence(&tracker, true, 40, [&](double t, const TrackResult&) {
    if (auto w = cut.takeWindowIfDue(t)) {
      windows.push_back(std::move(*w));
      hints.push_back(cut.motionHint());
    }
  });
  ASSERT_GT(st.frames, 0) << "opencv-doc photos missing";
  ASSERT_GE(windows.size(), 2u);
  KeyframeId next = 0;
  for (std::size_t w = 0; w < windows.size(); ++w) {
    const Submap& s = windows[w];
    EXPECT_EQ(s.validate(), "") << "window " << w;
    EXPECT_EQ(s.header.seq, w);
    EXPECT_EQ(s.header.session, 2u);
    EXPECT_EQ(s.header.agent, uuidFromSeed(4));
    ASSERT_EQ(s.cameras.size(), 1u);
    EXPECT_EQ(s.cameras[0].fx, test::roomK().fx);
    ASSERT_FALSE(s.keyframes.empty());
    EXPECT_EQ(s.keyframes.front().id, next) << "window " << w << " does not continue the last";
    next = s.keyframes.back().id + 1;
    EXPECT_DOUBLE_EQ(s.header.t_start, s.keyframes.front().stamp);
    EXPECT_DOUBLE_EQ(s.header.t_end, s.keyframes.back().stamp);
    EXPECT_FALSE(s.landmarks.empty());
    // Odometry edges: one per consecutive pair, composing to the window's poses.
    ASSERT_EQ(s.odometry.size(), s.keyframes.size() - 1);
    SE3 T = s.keyframes.front().T_A_C;
    for (std::size_t i = 0; i < s.odometry.size(); ++i) {
      EXPECT_EQ(s.odometry[i].from, s.keyframes[i].id);
      EXPECT_EQ(s.odometry[i].to, s.keyframes[i + 1].id);
      EXPECT_GT(s.odometry[i].information.diagonal().minCoeff(), 0);
      T = T * s.odometry[i].T_from_to;
    }
    EXPECT_LT(translationalDistance(T, s.keyframes.back().T_A_C), 1e-9);
    // Every keypoint link has a landmark in the window observing it back.
    std::map<LandmarkId, const Landmark*> lm;
    for (const auto& l : s.landmarks) lm[l.id] = &l;
    for (const auto& kf : s.keyframes)
      for (std::size_t i = 0; i < kf.keypoint_landmark.size(); ++i) {
        if (kf.keypoint_landmark[i] == kInvalidId) continue;
        ASSERT_TRUE(lm.count(kf.keypoint_landmark[i]));
        bool back = false;
        for (const auto& o : lm[kf.keypoint_landmark[i]]->observations)
          back = back || (o.keyframe == kf.id && o.keypoint == i);
        EXPECT_TRUE(back);
      }
    EXPECT_TRUE(hints[w].valid);
    EXPECT_GT(hints[w].dt_s, 0);
  }
  // Odometry continuity across windows: the step from the last keyframe of
  // window k to the first of k+1 is as small as steps inside windows.
  for (std::size_t w = 0; w + 1 < windows.size(); ++w) {
    const double gap = translationalDistance(windows[w].keyframes.back().T_A_C,
                                             windows[w + 1].keyframes.front().T_A_C);
    EXPECT_LT(gap, 0.25) << "between windows " << w << " and " << w + 1;
    EXPECT_GT(windows[w + 1].header.t_start, windows[w].header.t_end);
  }
  // Whatever is left, then nothing new: no window.
  cut.takeWindowIfDue(100.0);
  EXPECT_FALSE(cut.takeWindowIfDue(200.0).has_value());
}

TEST(SubmapWindow, ParamsValidate) {
  SubmapWindowParams p;
  EXPECT_TRUE(p.validate().ok());
  p.period_s = 0;
  EXPECT_FALSE(p.validate().ok());
  p.period_s = 5;
  p.odometry.trans_floor_m = 0;
  EXPECT_FALSE(p.validate().ok());
}

TEST(SubmapWindow, EdgesFollowTheOdometryNoiseModelAndLostFrames) {
  // Three keyframes 0.5 m apart sharing plenty of landmarks; tracking was lost
  // between the second and the third.
  std::vector<Keyframe> kfs(3);
  std::vector<Landmark> lms(60);
  for (std::size_t k = 0; k < kfs.size(); ++k) {
    kfs[k].id = k;
    kfs[k].stamp = double(k);
    kfs[k].T_A_C = SE3(Quat::Identity(), Vec3(0.5 * k, 0, 0));
  }
  for (std::size_t i = 0; i < lms.size(); ++i) {
    lms[i].id = i;
    lms[i].p_A = Vec3(0.1 * i, 1, 5);
    for (std::size_t k = 0; k < kfs.size(); ++k) {
      lms[i].observations.push_back({k, std::uint32_t(i)});
      kfs[k].keypoints.push_back({float(i), 10.f, 0, 5.f});
      kfs[k].descriptors.push_back({});
      kfs[k].keypoint_landmark.push_back(i);
    }
  }
  SubmapWindowParams p;
  const Submap s = buildWindow(kfs, lms, {0, 0, 1}, 0, kfs.size(), test::roomK(), SubmapHeader(), p);
  ASSERT_EQ(s.odometry.size(), 2u);
  const Mat6 expected = odometryInformation(s.odometry[0].T_from_to, 60, false, p.odometry);
  EXPECT_TRUE(s.odometry[0].information.isApprox(expected));
  EXPECT_NEAR(s.odometry[0].information(0, 0) / s.odometry[1].information(0, 0), p.odometry.lost_inflation, 1e-6);
  EXPECT_FALSE(s.keyframes[1].lost_before);
  EXPECT_TRUE(s.keyframes[2].lost_before);
  // A loss right before a window's first keyframe has no edge in that window:
  // the keyframe carries it, so that the server's bridge from the previous
  // window is as weak as the edge would be.
  const Submap later = buildWindow(kfs, lms, {0, 0, 1}, 2, kfs.size(), test::roomK(), SubmapHeader(), p);
  ASSERT_EQ(later.keyframes.size(), 1u);
  EXPECT_TRUE(later.odometry.empty());
  EXPECT_TRUE(later.keyframes[0].lost_before);
  // Keeping only the newest keyframes of a window keeps a loss among the dropped ones.
  Submap whole = buildWindow(kfs, lms, {0, 1, 0}, 0, kfs.size(), test::roomK(), SubmapHeader(), p);
  EXPECT_EQ(keepNewestKeyframes(&whole, 1), 2u);
  EXPECT_TRUE(whole.keyframes[0].lost_before);
}

TEST(SubmapWindow, DeferredWindowMergesIntoTheNextAndCanBeBounded) {
  TrackerParams p;
  p.window.period_s = 0.5;
  Tracker tracker(p, test::roomK(), 0.11);
  WindowCut cut(tracker, p.window);
  std::vector<Submap> windows;
  auto st = test::runRoomSequence(&tracker, true, 40, [&](double t, const TrackResult&) {
    if (auto w = cut.takeWindowIfDue(t)) windows.push_back(std::move(*w));
  });
  ASSERT_GT(st.frames, 0) << "opencv-doc photos missing";
  ASSERT_GE(windows.size(), 3u);
  auto merged = mergeWindows(windows[0], windows[1]);
  ASSERT_TRUE(merged.ok()) << merged.error();
  merged = mergeWindows(std::move(*merged), windows[2]);
  ASSERT_TRUE(merged.ok()) << merged.error();
  const Submap& m = *merged;
  EXPECT_EQ(m.validate(), "");
  EXPECT_EQ(m.keyframes.size(),
            windows[0].keyframes.size() + windows[1].keyframes.size() + windows[2].keyframes.size());
  EXPECT_EQ(m.header.seq, windows[2].header.seq);
  EXPECT_DOUBLE_EQ(m.header.t_start, windows[0].header.t_start);
  EXPECT_DOUBLE_EQ(m.header.t_end, windows[2].header.t_end);
  // A landmark seen in two windows is one landmark with the observations of both.
  std::size_t obs = 0;
  for (const Submap* w : {&windows[0], &windows[1], &windows[2]}) obs += w->observationCount();
  EXPECT_EQ(m.observationCount(), obs);
  std::set<LandmarkId> ids;
  for (const Landmark& l : m.landmarks) EXPECT_TRUE(ids.insert(l.id).second) << "landmark twice";

  // Bounded carry: the oldest keyframes go, what stays is consistent.
  Submap bounded = m;
  const std::size_t keep = windows[2].keyframes.size() + 1;
  EXPECT_EQ(keepNewestKeyframes(&bounded, keep), m.keyframes.size() - keep);
  EXPECT_EQ(bounded.keyframes.size(), keep);
  EXPECT_EQ(bounded.validate(), "");
  EXPECT_EQ(bounded.keyframes.back().id, m.keyframes.back().id);
  EXPECT_DOUBLE_EQ(bounded.header.t_start, bounded.keyframes.front().stamp);
  EXPECT_EQ(keepNewestKeyframes(&bounded, 1000), 0u);

  Submap other = windows[1];
  other.cameras[0].fx += 1;
  EXPECT_FALSE(mergeWindows(windows[0], other).ok());
}
