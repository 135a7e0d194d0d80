#include <gtest/gtest.h>

#include <cstdio>

#include "hermes/agent/covisibility.h"
#include "hermes/agent/tracker.h"
#include "plane_scene.h"
#include "room_sequence.h"

using namespace hermes;

TEST(LocalMapper, BundleAdjustmentKeepsOrImprovesTrackingAccuracy) {
  TrackerParams with, without;
  without.mapping.enable_ba = false;
  Tracker a(with, test::roomK(), 0.11), b(without, test::roomK(), 0.11);
  std::vector<LandmarkId> triangulated;
  int ba_runs = 0, ba_sizes_consistent = 0;
  auto sa = test::runRoomSequence(&a, true, 30, [&](double, const TrackResult& r) {
    for (const auto& t : r.mapping.triangulated) triangulated.push_back(t.first);
    const LocalMappingStats& m = r.mapping;
    if (!r.new_keyframe || m.ba_ms <= 0) return;
    ++ba_runs;  // the problem-size counters describe the solved window
    ba_sizes_consistent += m.points > 0 && m.free_keyframes > 0 && m.fixed_keyframes > 0 &&
                           m.observations >= m.points && m.residuals >= 2 * m.observations &&
                           m.residuals <= 3 * m.observations && m.ba_iterations >= 1 &&
                           m.total_ms >= m.ba_ms;
  });
  ASSERT_GT(sa.frames, 0) << "opencv-doc photos missing";
  // Triangulated points lie on the scene's planes (world = first camera's pose · odometry).
  const auto planes = test::roomCornerScene();
  const SE3 T_W_O = test::roomGroundTruth(0);
  int checked = 0, on_plane = 0;
  for (LandmarkId id : triangulated) {
    if (a.isLandmarkBad(id)) continue;
    const Vec3 p = T_W_O * a.landmarks()[id].p_A;
    double best = 1e9;
    for (const auto& pl : planes) best = std::min(best, std::abs((p - pl.origin).dot(pl.e1.cross(pl.e2))));
    ++checked;
    // Two-view depth error grows with range: allow 5 % of the distance.
    on_plane += best < 0.05 * a.landmarks()[id].p_A.norm();
  }
  std::printf("triangulated %zu points, %d kept, %d within 5 %% of their range of a plane\n", triangulated.size(),
              checked, on_plane);
  EXPECT_GT(checked, 0);
  EXPECT_GE(on_plane, 0.8 * checked);  // measured 77 of 86
  auto sb = test::runRoomSequence(&b, true, 30);
  std::printf("stereo room 30 frames: ATE RMSE with BA %.4f m (%d kf, BA mean %.1f ms max %.1f ms), "
              "without %.4f m\n",
              sa.rmse, sa.keyframes, sa.mean_ba_ms, sa.max_ba_ms, sb.rmse);
  EXPECT_EQ(sa.lost, 0);
  EXPECT_LT(sa.rmse, 0.01);
  EXPECT_LT(sa.rmse, sb.rmse * 1.5 + 0.001);
  EXPECT_GT(sa.mean_ba_ms, 0);
  EXPECT_GT(ba_runs, 0);
  EXPECT_EQ(ba_sizes_consistent, ba_runs);
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
    for (LandmarkId id : kf.keypoint_landmark) {
      if (id != kInvalidId) {
        EXPECT_FALSE(t.isLandmarkBad(id));
      }
    }
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

// ---- Accuracy on a short rendered EuRoC MH_01 stereo clip -----------------

#include <chrono>

#include <opencv2/core.hpp>

#include "hermes/core/evaluation.h"
#include "hermes/core/render/raycaster.h"
#include "hermes/core/render/rig.h"
#include "hermes/core/render/scene.h"
#include "hermes/core/render/sensor.h"
#include "hermes/core/stereo_rig.h"
#include "hermes/core/trajectory.h"

namespace {

struct ClipResult {
  double ate_m = -1;
  int frames = 0, lost = 0, keyframes = 0;
  double mean_ba_ms = 0, track_s = 0;
  double path_m = 0;  ///< ground-truth path length of the clip
};

/// Renders `seconds` of MH_01 (from `offset_s` after the start) at `hz`, raw
/// distorted EuRoC cam0/cam1 images with sensor noise, rectifies and tracks them;
/// ATE (SE(3) alignment) of the body trajectory against ground truth.
ClipResult trackRenderedClip(bool ba, double offset_s, double seconds, double hz) {
  ClipResult out;
  auto gt = readTumTrajectory(std::string(HERMES_TRAJECTORY_DIR) + "/MH_01_easy.txt");
  if (!gt.ok()) return out;
  std::vector<Vec3> pos;
  for (const auto& p : *gt) pos.push_back(p.T_W_B.translation());
  static auto scene = render::buildScene(pos, render::SceneParams{});
  if (!scene.ok()) return out;
  StereoRig rig{render::eurocCam0(), render::eurocCam1()};
  auto rect = rectify(rig);
  if (!rect.ok()) return out;
  render::Raycaster rc0(*scene, render::RayGrid::fromRadtan(rig.left));
  render::Raycaster rc1(*scene, render::RayGrid::fromRadtan(rig.right));
  render::Sensor sensor(render::SensorParams{}, 11, 752, 480);
  TrackerParams p;
  p.mapping.enable_ba = ba;
  Tracker tracker(p, rect->K, rect->baseline);
  Trajectory est;
  render::RenderOutput ro;
  double ba_sum = 0;
  int ba_n = 0;
  const int n = int(seconds * hz);
  for (int k = 0; k < n; ++k) {
    const double t = gt->front().t + offset_s + k / hz;
    SE3 T_W_B;
    if (!interpolatePose(*gt, t, &T_W_B)) break;
    rc0.render(T_W_B * rig.left.T_B_C, &ro);
    cv::Mat l = sensor.expose(ro.radiance, t, 0);
    rc1.render(T_W_B * rig.right.T_B_C, &ro);
    cv::Mat r = sensor.expose(ro.radiance, t, 1);
    CameraFrame f;
    f.stamp = t;
    rect->rectifyImages(l, r, &f.left, &f.right);
    const auto c0 = std::chrono::steady_clock::now();
    auto res = tracker.feed(f);
    out.track_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - c0).count();
    if (!res.ok()) return out;
    ++out.frames;
    if (res->mapping.ba_ms > 0) {
      ba_sum += res->mapping.ba_ms;
      ++ba_n;
    }
    if (res->status != TrackingStatus::kOk) {
      ++out.lost;
      continue;
    }
    if (!est.empty()) {
      SE3 prev;
      interpolatePose(*gt, est.back().t, &prev);
      out.path_m += (T_W_B.translation() - prev.translation()).norm();
    }
    est.push_back({t, res->T_W_C * rect->T_B_Crect.inverse()});  // odometry <- body
  }
  out.keyframes = int(tracker.keyframes().size());
  out.mean_ba_ms = ba_n ? ba_sum / ba_n : 0;
  auto assoc = eval::associate(*gt, est, 0.01);
  if (!assoc.ok() || assoc->matched() < 10) return out;
  auto ate = eval::computeAte(*assoc, eval::AlignMode::kSE3);
  if (ate.ok()) out.ate_m = ate->trans_m.rmse;
  return out;
}

}  // namespace

TEST(LocalMapper, RenderedEurocClipAccuracy) {
  // Measured (60-65 s of MH_01, 2.3 m path): ATE 3.9 mm with local BA, 5.0 mm
  // without (triangulation/fusion on in both);
  // BA off: set ba to false;
  // only the BA run is kept here to stay within the unit-test time budget.
  for (bool ba : {true}) {
    const auto c0 = std::chrono::steady_clock::now();
    ClipResult r = trackRenderedClip(ba, 60.0, 5.0, 10.0);
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - c0).count();
    std::printf("MH_01 rendered 5 s @10 Hz, BA %s: ATE %.4f m, %d frames, %d lost, %d kf, "
                "BA mean %.1f ms, tracking %.2f s, total %.1f s, path %.2f m\n",
                ba ? "on" : "off", r.ate_m, r.frames, r.lost, r.keyframes, r.mean_ba_ms,
                r.track_s, wall, r.path_m);
    ASSERT_GT(r.frames, 0) << "ground truth or render failed";
    EXPECT_EQ(r.lost, 0);
    EXPECT_GE(r.ate_m, 0);
    EXPECT_GT(r.path_m, 0.5);   // the clip really moves
    EXPECT_LT(r.ate_m, 0.015);  // measured 0.0039 m
  }
}
