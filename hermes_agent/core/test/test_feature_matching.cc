#include <gtest/gtest.h>

#include <random>

#include "hermes/agent/feature_matching.h"
#include "hermes/agent/pose_estimation.h"

#include "hermes/distill/synthetic_window.h"

using namespace hermes;

namespace {

Descriptor randomDescriptor(std::mt19937& rng) {
  Descriptor d;
  for (auto& b : d) b = std::uint8_t(rng() & 0xff);
  return d;
}

Descriptor flipBits(Descriptor d, int bits, std::mt19937& rng) {
  for (int i = 0; i < bits; ++i) {
    const int b = int(rng() % 256);
    d[b / 8] ^= std::uint8_t(1u << (b % 8));
  }
  return d;
}

/// A local map of landmarks and a frame whose keypoints are their noisy
/// projections (descriptors with a few flipped bits, angles rotated by 20 deg)
/// plus random distractors.
struct Scene {
  std::vector<LandmarkView> landmarks;
  FeatureSet frame;
  std::vector<int> truth;  // landmark -> keypoint, -1 if not visible
};

Scene makeScene(std::mt19937& rng, const SE3& T_C_W, const PinholeIntrinsics& K, int n) {
  Scene s;
  s.frame.width = K.width;
  s.frame.height = K.height;
  std::uniform_real_distribution<double> ux(-50, K.width + 50), uy(-50, K.height + 50),
      uz(1.0, 10.0), ua(0, 340);
  std::normal_distribution<double> noise(0, 0.7);
  const SE3 T_W_C = T_C_W.inverse();
  for (int i = 0; i < n; ++i) {
    const double u = ux(rng), v = uy(rng), z = uz(rng);
    LandmarkView l;
    l.p_W = T_W_C * Vec3((u - K.cx) / K.fx * z, (v - K.cy) / K.fy * z, z);
    l.descriptor = randomDescriptor(rng);
    l.angle = float(ua(rng));
    s.landmarks.push_back(l);
    const Vec2 uv(u + noise(rng), v + noise(rng));
    if (!K.inImage(uv)) {
      s.truth.push_back(-1);
      continue;
    }
    s.truth.push_back(int(s.frame.keypoints.size()));
    Keypoint k;
    k.u = float(uv.x());
    k.v = float(uv.y());
    s.frame.keypoints.push_back(k);
    s.frame.descriptors.push_back(flipBits(l.descriptor, 20, rng));
    s.frame.angles.push_back(l.angle + 20.f);
  }
  std::uniform_real_distribution<double> px(0, K.width), py(0, K.height);
  for (int i = 0; i < n / 2; ++i) {  // distractors
    Keypoint k;
    k.u = float(px(rng));
    k.v = float(py(rng));
    s.frame.keypoints.push_back(k);
    s.frame.descriptors.push_back(randomDescriptor(rng));
    s.frame.angles.push_back(float(ua(rng)));
  }
  return s;
}

}  // namespace

TEST(FeatureMatching, GridQueryEqualsBruteForce) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> ux(0, 752), uy(0, 480);
  std::vector<Keypoint> kps(2000);
  for (auto& k : kps) {
    k.u = float(ux(rng));
    k.v = float(uy(rng));
    k.octave = std::uint8_t(rng() % 8);
  }
  KeypointGrid grid(kps, 752, 480, 16);
  for (int q = 0; q < 200; ++q) {
    const double u = ux(rng) * 1.1 - 30, v = uy(rng) * 1.1 - 20, r = 3 + q % 40;
    auto got = grid.query(u, v, r, 2, 5);
    std::sort(got.begin(), got.end());
    std::vector<int> want;
    for (int i = 0; i < int(kps.size()); ++i) {
      const double du = kps[i].u - u, dv = kps[i].v - v;
      if (du * du + dv * dv <= r * r && kps[i].octave >= 2 && kps[i].octave <= 5)
        want.push_back(i);
    }
    ASSERT_EQ(got, want) << "query " << q;
  }
}

TEST(FeatureMatching, ProjectionMatchingThenPose) {
  std::mt19937 rng(9);
  const PinholeIntrinsics K = distill::eurocCam0Intrinsics();
  const SE3 T_C_W(expSO3(Vec3(0.1, -0.2, 0.05)), Vec3(0.3, -0.1, 0.5));
  Scene s = makeScene(rng, T_C_W, K, 600);
  // Predicted pose a few pixels off (as from a constant-velocity model).
  const SE3 pred = SE3::exp((Vec6() << 0.01, 0.005, -0.01, 0.004, -0.006, 0.003).finished()) *
                   T_C_W;
  KeypointGrid grid(s.frame.keypoints, K.width, K.height);
  auto match = matchByProjection(s.landmarks, pred, K, s.frame, grid, ProjectionMatchParams());
  int visible = 0, correct = 0, wrong = 0;
  for (size_t i = 0; i < match.size(); ++i) {
    visible += s.truth[i] >= 0;
    if (match[i] < 0) continue;
    (match[i] == s.truth[i] ? correct : wrong)++;
  }
  EXPECT_GT(visible, 300);
  EXPECT_GT(correct, 0.9 * visible);
  EXPECT_EQ(wrong, 0);

  Correspondences c;
  for (size_t i = 0; i < match.size(); ++i) {
    if (match[i] < 0) continue;
    c.p_W.push_back(s.landmarks[i].p_W);
    c.uv.push_back(Vec2(s.frame.keypoints[match[i]].u, s.frame.keypoints[match[i]].v));
  }
  auto est = refinePose(c, K, pred, PoseEstimationParams());
  ASSERT_TRUE(est.ok()) << est.error();
  EXPECT_LT(translationalDistance(est->T_C_W, T_C_W), 0.01);
  EXPECT_LT(angularDistance(est->T_C_W, T_C_W) * 180 / M_PI, 0.1);
}

TEST(FeatureMatching, OrientationConsistencyDropsOddRotations) {
  std::mt19937 rng(13);
  const PinholeIntrinsics K = distill::eurocCam0Intrinsics();
  const SE3 T_C_W;
  Scene s = makeScene(rng, T_C_W, K, 300);
  // A tenth of the true matches get an inconsistent orientation change.
  std::vector<int> odd;
  for (size_t i = 0; i < s.landmarks.size(); i += 10)
    if (s.truth[i] >= 0) {
      s.frame.angles[s.truth[i]] = s.landmarks[i].angle + 150.f;
      odd.push_back(int(i));
    }
  KeypointGrid grid(s.frame.keypoints, K.width, K.height);
  ProjectionMatchParams p;
  auto with = matchByProjection(s.landmarks, T_C_W, K, s.frame, grid, p);
  p.check_orientation = false;
  auto without = matchByProjection(s.landmarks, T_C_W, K, s.frame, grid, p);
  for (int i : odd) {
    EXPECT_EQ(with[i], -1);
    EXPECT_EQ(without[i], s.truth[i]);
  }
  int kept = 0;
  for (size_t i = 0; i < with.size(); ++i) kept += with[i] >= 0;
  EXPECT_GT(kept, int(s.frame.size() / 3));
}
