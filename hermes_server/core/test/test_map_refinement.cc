// Map refinement (map_refinement.h): the Ceres costs' Jacobians against numeric
// differences, a synthetic two-robot scene with noisy poses and landmarks and
// exact observations (the refinement must lower both errors by a clear factor),
// a perfect map left unchanged, and the global map's version-3 additions (loop
// keypoint pairs, refined edges) through save / load.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstring>
#include <map>
#include <random>
#include <set>
#include <tuple>

#include <ceres/ceres.h>

#include "hermes/core/crc32.h"
#include "hermes/server/global_map.h"
#include "hermes/server/map_refinement.h"

namespace hermes {
namespace server {
namespace {

constexpr int kKeyframes = 14;
constexpr int kLoopKf = 7;

PinholeIntrinsics camera() {
  PinholeIntrinsics c;
  c.fx = c.fy = 450;
  c.cx = 320;
  c.cy = 240;
  c.width = 640;
  c.height = 480;
  return c;
}

/// Two robots walking side by side along x, looking at a wall of points at
/// z = 4 m (world frame = both agent frames); every keyframe observes every
/// point it sees, exactly, with depth. Robot 1's keyframe kLoopKf is tied to
/// robot 0's keyframe kLoopKf by a loop whose kept pairs are the shared points.
struct Scene {
  GlobalMap map;
  std::vector<Vec3> points;                       // truth, indexed by landmark id
  std::map<KeyframeKey, SE3> truth;               // keyframe poses
};

SE3 truePose(int robot, int i) {
  const Vec3 t(0.15 * i, 0.3 * robot - 0.15, 0.05 * std::sin(0.5 * i + robot));
  const Quat q(Eigen::AngleAxisd(0.02 * i - 0.03 * robot, Vec3::UnitY()));
  return SE3(q, t);
}

Scene makeScene() {
  Scene s;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> ux(-2.0, 4.5), uy(-1.5, 1.5), uz(3.5, 4.5);
  for (int j = 0; j < 400; ++j) s.points.emplace_back(ux(rng), uy(rng), uz(rng));
  const PinholeIntrinsics cam = camera();
  for (std::uint32_t robot = 0; robot < 2; ++robot) {
    TrajectoryMap& t = s.map.trajectories[{robot, 0}];
    t.agent = robot;
    t.anchored = true;
    for (int i = 0; i < kKeyframes; ++i) {
      StoredKeyframe sk;
      sk.keyframe.id = static_cast<KeyframeId>(i);
      sk.keyframe.stamp = i;
      sk.keyframe.T_A_C = truePose(robot, i);
      sk.T_W_C = sk.keyframe.T_A_C;
      sk.camera = cam;
      for (std::size_t j = 0; j < s.points.size(); ++j) {
        const Vec3 p_C = sk.T_W_C.inverse() * s.points[j];
        const Vec2 uv = cam.project(p_C);
        if (p_C.z() < 0.5 || !cam.inImage(uv, 5)) continue;
        Keypoint kp;
        kp.u = static_cast<float>(uv.x());
        kp.v = static_cast<float>(uv.y());
        kp.depth = static_cast<float>(p_C.z());
        const auto index = static_cast<std::uint32_t>(sk.keyframe.keypoints.size());
        sk.keyframe.keypoints.push_back(kp);
        sk.keyframe.descriptors.emplace_back();
        sk.keyframe.keypoint_landmark.push_back(j);
        auto& lm = t.landmarks[j];
        lm.landmark.id = j;
        lm.landmark.p_A = s.points[j];
        lm.landmark.observations.push_back(Observation{sk.keyframe.id, index});
      }
      s.truth[KeyframeKey{robot, 0, sk.keyframe.id}] = sk.T_W_C;
      t.keyframes[sk.keyframe.id] = std::move(sk);
    }
    for (auto& [id, lm] : t.landmarks) GlobalMap::anchorLandmark(t, &lm);
    for (int i = 0; i + 1 < kKeyframes; ++i) {  // exact odometry, 1 cm / 10 mrad sigmas
      OdometryEdge e;
      e.from = i;
      e.to = i + 1;
      e.T_from_to = truePose(robot, i).inverse() * truePose(robot, i + 1);
      e.information = Mat6::Identity() * 1e4;
      t.odometry[{e.from, e.to}] = e;
    }
  }
  // The loop: robot 0's keyframe kLoopKf (a) <-> robot 1's (b); pairs = shared points.
  LoopEdge loop;
  loop.id = 1;
  loop.a = KeyframeKey{0, 0, kLoopKf};
  loop.b = KeyframeKey{1, 0, kLoopKf};
  loop.T_a_b = s.truth[loop.a].inverse() * s.truth[loop.b];
  loop.accepted = true;
  const Keyframe& ka = s.map.keyframe(loop.a)->keyframe;
  const Keyframe& kb = s.map.keyframe(loop.b)->keyframe;
  for (std::uint32_t i = 0; i < ka.keypoints.size(); ++i)
    for (std::uint32_t k = 0; k < kb.keypoints.size(); ++k)
      if (ka.keypoint_landmark[i] == kb.keypoint_landmark[k])
        loop.matches.push_back(LoopMatch{kLoopKf, i, kLoopKf, k});
  loop.inliers = static_cast<int>(loop.matches.size());
  s.map.loops.push_back(loop);
  return s;
}

MapRefinementParams params() {
  MapRefinementParams p;
  p.enabled = true;
  p.neighbours = 3;
  p.max_iterations = 50;
  p.max_time_s = 10;
  return p;
}

struct Errors {
  double pose_m = 0, landmark_m = 0;
};

/// RMS over the window keyframes (kLoopKf +- 3, both robots) and the landmarks
/// they observe, against the truth.
Errors errors(const Scene& s) {
  Errors e;
  int n = 0;
  std::set<LandmarkId> lms[2];
  for (std::uint32_t robot = 0; robot < 2; ++robot)
    for (int i = kLoopKf - 3; i <= kLoopKf + 3; ++i) {
      const KeyframeKey k{robot, 0, static_cast<KeyframeId>(i)};
      const StoredKeyframe* sk = s.map.keyframe(k);
      e.pose_m += (sk->T_W_C.translation() - s.truth.at(k).translation()).squaredNorm();
      ++n;
      for (LandmarkId l : sk->keyframe.keypoint_landmark) lms[robot].insert(l);
    }
  e.pose_m = std::sqrt(e.pose_m / n);
  n = 0;
  for (std::uint32_t robot = 0; robot < 2; ++robot) {
    const TrajectoryMap& t = s.map.trajectories.at({robot, 0});
    for (LandmarkId l : lms[robot]) {
      const StoredLandmark& lm = t.landmarks.at(l);
      const Vec3 p_W = t.keyframes.at(lm.anchor).T_W_C * lm.p_anchor;
      e.landmark_m += (p_W - s.points[l]).squaredNorm();
      ++n;
    }
  }
  e.landmark_m = std::sqrt(e.landmark_m / n);
  return e;
}

TEST(MapRefinement, CostJacobiansMatchNumericDifferences) {
  std::mt19937 rng(3);
  std::normal_distribution<double> n01(0, 1);
  for (int trial = 0; trial < 20; ++trial) {
    Quat q(Eigen::AngleAxisd(0.3 * n01(rng), Vec3(n01(rng), n01(rng), n01(rng)).normalized()));
    double qv[4] = {q.x(), q.y(), q.z(), q.w()};
    double t[3] = {0.2 * n01(rng), 0.2 * n01(rng), 0.2 * n01(rng)};
    const Vec3 p = q * Vec3(n01(rng), n01(rng), 4 + n01(rng)) + Vec3(t[0], t[1], t[2]);
    double pv[3] = {p.x(), p.y(), p.z()};
    const double* params[3] = {qv, t, pv};
    const detail::ReprojectionCost rc{300, 200, 450, 440, 320, 240, 1 / 1.2};
    const detail::InverseDepthCost dc{1 / 4.1, 45, 1.0};
    ceres::AutoDiffCostFunction<detail::ReprojectionCost, 2, 4, 3, 3> ad_r(new detail::ReprojectionCost(rc));
    ceres::NumericDiffCostFunction<detail::ReprojectionCost, ceres::CENTRAL, 2, 4, 3, 3> nd_r(
        new detail::ReprojectionCost(rc));
    ceres::AutoDiffCostFunction<detail::InverseDepthCost, 1, 4, 3, 3> ad_d(new detail::InverseDepthCost(dc));
    ceres::NumericDiffCostFunction<detail::InverseDepthCost, ceres::CENTRAL, 1, 4, 3, 3> nd_d(
        new detail::InverseDepthCost(dc));
    for (auto [ad, nd, m] : {std::tuple<ceres::CostFunction*, ceres::CostFunction*, int>{&ad_r, &nd_r, 2},
                             {&ad_d, &nd_d, 1}}) {
      double ra[2], rn[2];
      std::vector<double> ja[3], jn[3];
      double* pa[3];
      double* pn[3];
      const int sizes[3] = {4, 3, 3};
      for (int b = 0; b < 3; ++b) {
        ja[b].resize(m * sizes[b]);
        jn[b].resize(m * sizes[b]);
        pa[b] = ja[b].data();
        pn[b] = jn[b].data();
      }
      ASSERT_TRUE(ad->Evaluate(params, ra, pa));
      ASSERT_TRUE(nd->Evaluate(params, rn, pn));
      for (int i = 0; i < m; ++i) EXPECT_NEAR(ra[i], rn[i], 1e-9);
      for (int b = 0; b < 3; ++b)
        for (int i = 0; i < m * sizes[b]; ++i)
          EXPECT_NEAR(ja[b][i], jn[b][i], 1e-5 * std::max(1.0, std::abs(ja[b][i])))
              << "block " << b << " entry " << i;
    }
  }
}

TEST(MapRefinement, LowersPoseAndLandmarkErrorOfTwoRobotWindow) {
  Scene s = makeScene();
  std::mt19937 rng(11);
  std::normal_distribution<double> n01(0, 1);
  // Noise on the window's keyframes (2 cm, 0.5 deg) and on every landmark (3 cm).
  for (std::uint32_t robot = 0; robot < 2; ++robot) {
    TrajectoryMap& t = s.map.trajectories.at({robot, 0});
    for (int i = kLoopKf - 3; i <= kLoopKf + 3; ++i) {
      StoredKeyframe& sk = t.keyframes.at(i);
      const Vec6 xi = (Vec6() << 0.02 * n01(rng), 0.02 * n01(rng), 0.02 * n01(rng), 0.009 * n01(rng),
                       0.009 * n01(rng), 0.009 * n01(rng)).finished();
      sk.T_W_C = sk.T_W_C * SE3::exp(xi);
    }
    for (auto& [id, lm] : t.landmarks)
      lm.p_anchor += 0.03 * Vec3(n01(rng), n01(rng), n01(rng));
  }
  const Errors before = errors(s);
  const TieConsistency ties_before = measureLoopTies(s.map);
  const MapRefinementResult r = refineAroundLoops(&s.map, {1}, params());
  const Errors after = errors(s);
  const TieConsistency ties_after = measureLoopTies(s.map);
  ASSERT_TRUE(r.applied) << r.termination;
  std::printf("window: %d free / %d held keyframes, %d landmarks, %d residuals (%d ties), %d iterations, %.1f ms\n"
              "pose RMS %.2f -> %.4f mm, landmark RMS %.2f -> %.4f mm, cross-robot tie reprojection RMS %.3f -> %.4f px\n",
              r.free_keyframes, r.fixed_keyframes, r.landmarks, r.residuals, r.ties, r.iterations, r.time_ms,
              1e3 * before.pose_m, 1e3 * after.pose_m, 1e3 * before.landmark_m, 1e3 * after.landmark_m,
              ties_before.cross_reproj_rms_px, ties_after.cross_reproj_rms_px);
  EXPECT_EQ(r.free_keyframes, 14);
  EXPECT_GT(r.fixed_keyframes, 0);
  EXPECT_GT(r.ties, 50);
  EXPECT_EQ(r.odometry, 2 * 8);  // kLoopKf +- 3 free: 6 edges inside, one to each held side
  EXPECT_LT(after.pose_m, before.pose_m / 10) << before.pose_m << " -> " << after.pose_m;
  EXPECT_LT(after.landmark_m, before.landmark_m / 5) << before.landmark_m << " -> " << after.landmark_m;
  EXPECT_LT(ties_after.cross_reproj_rms_px, ties_before.cross_reproj_rms_px / 5);
  // The pose-graph edges inside the window keep the refined relative poses.
  const KeyframeKey a{0, 0, kLoopKf}, b{1, 0, kLoopKf}, a1{0, 0, kLoopKf + 1};
  ASSERT_TRUE(s.map.refined_edges.count({a, b}));
  ASSERT_TRUE(s.map.refined_edges.count({a, a1}));
  const SE3 T = s.map.refined_edges.at({a, a1});
  EXPECT_LT((T.translation() - (s.map.keyframe(a)->T_W_C.inverse() * s.map.keyframe(a1)->T_W_C).translation()).norm(), 1e-12);
}

TEST(MapRefinement, LeavesAPerfectMapUnchanged) {
  Scene s = makeScene();
  const GlobalMap before = s.map;
  const MapRefinementResult r = refineAroundLoops(&s.map, {1}, params());
  ASSERT_TRUE(r.ran) << r.termination;
  // The observations are floats (pixels ~3e-5 px, depths ~5e-7 m apart at 4 m):
  // "unchanged" means within what that rounding allows, 10 um.
  EXPECT_LT(r.max_pose_change_m, 1e-5);
  for (const auto& [tid, t] : s.map.trajectories) {
    for (const auto& [id, kf] : t.keyframes) {
      const SE3& T0 = before.trajectories.at(tid).keyframes.at(id).T_W_C;
      EXPECT_LT((kf.T_W_C.translation() - T0.translation()).norm(), 1e-5);
      EXPECT_LT(rotationAngle((T0.inverse() * kf.T_W_C).rotation()), 1e-5);
    }
    for (const auto& [id, lm] : t.landmarks)
      EXPECT_LT((lm.p_anchor - before.trajectories.at(tid).landmarks.at(id).p_anchor).norm(), 1e-5);
  }
  EXPECT_LT(measureLoopTies(s.map).cross_reproj_rms_px, 1e-3);
}

TEST(MapRefinement, NothingToDoWithoutAcceptedLoops) {
  Scene s = makeScene();
  s.map.loops[0].accepted = false;
  const MapRefinementResult r = refineAroundLoops(&s.map, {1}, params());
  EXPECT_FALSE(r.ran);
  EXPECT_TRUE(s.map.refined_edges.empty());
}

TEST(MapRefinement, LoopPairsAndRefinedEdgesSurviveSaveAndLoad) {
  Scene s = makeScene();
  ASSERT_TRUE(refineAroundLoops(&s.map, {1}, params()).applied);
  ASSERT_FALSE(s.map.refined_edges.empty());
  ASSERT_FALSE(s.map.loops[0].matches.empty());
  const std::vector<std::uint8_t> bytes = s.map.toBytes();
  auto loaded = GlobalMap::fromBytes(bytes, "test");
  ASSERT_TRUE(loaded.ok()) << loaded.error();
  EXPECT_EQ(loaded->loops[0].matches, s.map.loops[0].matches);
  ASSERT_EQ(loaded->refined_edges.size(), s.map.refined_edges.size());
  for (const auto& [ends, T] : s.map.refined_edges) {
    const SE3& L = loaded->refined_edges.at(ends);
    EXPECT_EQ(L.translation(), T.translation());
    EXPECT_LT((L.quat().coeffs() - T.quat().coeffs()).norm(), 1e-15);  // re-normalised on load
  }
  EXPECT_EQ(loaded->toBytes().size(), bytes.size());
  // A version-2 file (before the loop pairs) is refused with a clear message.
  std::vector<std::uint8_t> old = bytes;
  const std::uint32_t v2 = 2;
  std::memcpy(old.data() + 4, &v2, 4);
  const std::uint32_t crc = crc32(old.data(), old.size() - 4);
  std::memcpy(old.data() + old.size() - 4, &crc, 4);
  auto refused = GlobalMap::fromBytes(old, "old");
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().find("unsupported version 2 (this build reads 3)"), std::string::npos)
      << refused.error();
  // A kept pair naming a keypoint the keyframe does not hold is refused.
  GlobalMap bad = s.map;
  bad.loops[0].matches[0].kp_a = 100000;
  EXPECT_FALSE(GlobalMap::fromBytes(bad.toBytes(), "bad").ok());
}

TEST(MapRefinement, ParamsValidate) {
  MapRefinementParams p;
  EXPECT_TRUE(p.validate().ok());
  p.loss = "l1";
  EXPECT_FALSE(p.validate().ok());
  p = MapRefinementParams();
  p.max_time_s = -1;
  EXPECT_FALSE(p.validate().ok());
}

}  // namespace
}  // namespace server
}  // namespace hermes
