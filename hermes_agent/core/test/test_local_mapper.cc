#include <gtest/gtest.h>

#include <cstdio>

#include "hermes/agent/covisibility.h"
#include "hermes/agent/tracker.h"
#include "room_sequence.h"

using namespace hermes;

TEST(LocalMapper, BundleAdjustmentKeepsOrImprovesTrackingAccuracy) {
  TrackerParams with, without;
  without.mapping.enable_ba = false;
  Tracker a(with, test::roomK(), 0.11), b(without, test::roomK(), 0.11);
  auto sa = test::runRoomSequence(&a, true, 40);
  ASSERT_GT(sa.frames, 0) << "opencv-doc photos missing";
  auto sb = test::runRoomSequence(&b, true, 40);
  std::printf("stereo room 40 frames: ATE RMSE with BA %.4f m (%d kf, BA mean %.1f ms max %.1f ms), "
              "without %.4f m\n",
              sa.rmse, sa.keyframes, sa.mean_ba_ms, sa.max_ba_ms, sb.rmse);
  EXPECT_EQ(sa.lost, 0);
  EXPECT_LT(sa.rmse, 0.01);
  EXPECT_LT(sa.rmse, sb.rmse * 1.5 + 0.001);
  EXPECT_GT(sa.mean_ba_ms, 0);
}

TEST(LocalMapper, MapStaysConsistentAfterCullingAndOutlierRemoval) {
  Tracker t(TrackerParams(), test::roomK(), 0.11);
  int culled = 0;
  auto st = test::runRoomSequence(&t, false, 30, [&](double, const TrackResult& r) {
    culled += r.mapping.culled;
  });
  ASSERT_GT(st.frames, 0);
  const auto& kfs = t.keyframes();
  const auto& lms = t.landmarks();
  ASSERT_GT(kfs.size(), 3u);
  int bad = 0;
  for (const auto& l : lms) {
    if (t.isLandmarkBad(l.id)) {
      ++bad;
      EXPECT_TRUE(l.observations.empty());
    }
    for (const auto& o : l.observations) {
      ASSERT_LT(o.keyframe, kfs.size());
      EXPECT_EQ(kfs[o.keyframe].keypoint_landmark[o.keypoint], l.id);
    }
  }
  for (const auto& kf : kfs)
    for (LandmarkId id : kf.keypoint_landmark)
      if (id != kInvalidId) EXPECT_FALSE(t.isLandmarkBad(id));
  EXPECT_GE(bad, culled);
  std::printf("RGB-D room: %zu landmarks, %d culled, %d bad\n", lms.size(), culled, bad);
  // Consecutive keyframes are covisible.
  for (std::size_t k = 1; k < kfs.size(); ++k) {
    const auto cov = covisibleKeyframes(kfs, lms, k, 1);
    bool prev = false;
    for (const auto& [id, n] : cov) prev = prev || (id == k - 1 && n == sharedLandmarks(kfs, lms, k, k - 1));
    EXPECT_TRUE(prev) << "keyframe " << k;
  }
}
