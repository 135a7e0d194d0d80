// Landmark stability, information gain with motion attention, α/β rule and the
// monotone submodularity of f(S).
#include <gtest/gtest.h>

#include <random>

#include "distill_fixture.h"
#include "hermes/distill/scores.h"

namespace hermes {
namespace distill {
namespace {

TEST(Scores, BearingJacobianMatchesNumericalDerivative) {
  std::mt19937_64 rng(3);
  std::normal_distribution<double> n(0.0, 1.0);
  for (int trial = 0; trial < 20; ++trial) {
    const Vec3 P(n(rng), n(rng), 4.0 + std::abs(n(rng)));
    const Vec3 p = (P + 0.01 * Vec3(n(rng), n(rng), n(rng))).normalized();
    // r(φ, ρ) = p × (exp(φ) P + ρ); W = −∂r/∂[φ; ρ].
    auto r = [&](const Vec6& d) { return Vec3(p.cross(expSO3(d.head<3>()) * P + d.tail<3>())); };
    Eigen::Matrix<double, 3, 6> J;
    const double h = 1e-6;
    for (int c = 0; c < 6; ++c) {
      Vec6 d = Vec6::Zero();
      d[c] = h;
      J.col(c) = (r(d) - r(-d)) / (2 * h);
    }
    EXPECT_LT((bearingJacobian(p, P) + J).norm(), 1e-6);
  }
}

TEST(Scores, InformationGainIsZeroWithoutInformationAndGrowsWithObservations) {
  const double delta = 1e-3;
  EXPECT_NEAR(informationGain(Mat6::Zero(), delta), 0.0, 1e-9);
  Mat6 L = Mat6::Zero();
  double prev = 0;
  std::mt19937_64 rng(5);
  std::normal_distribution<double> n(0.0, 1.0);
  for (int k = 0; k < 5; ++k) {
    const Vec3 P(n(rng), n(rng), 5.0);
    const auto W = bearingJacobian(P.normalized(), P);
    L += W.transpose() * W;
    const double q = informationGain(L, delta);
    EXPECT_GT(q, prev + 1e-6);
    prev = q;
  }
}

// Camera moving along +x looking along +z; two landmarks at equal depth seen by
// the same two keyframes: one ahead of the motion (stays in view), one behind
// it (about to leave the image).
Submap twoLandmarkWindow() {
  Submap s;
  s.cameras.push_back(eurocCam0Intrinsics());
  const PinholeIntrinsics& K = s.cameras[0];
  const Vec3 ahead(3.0, 0.0, 5.0), behind(-3.85, 0.0, 5.0);
  for (int k = 0; k < 2; ++k) {
    Keyframe kf;
    kf.id = static_cast<KeyframeId>(k + 1);
    kf.stamp = 0.1 * k;
    kf.T_A_C = SE3(Mat3::Identity(), Vec3(0.1 * k, 0, 0));
    for (const Vec3& P : {ahead, behind}) {
      const Vec2 uv = K.project(kf.T_A_C.inverse() * P);
      EXPECT_TRUE(K.inImage(uv));
      kf.keypoints.push_back({static_cast<float>(uv.x()), static_cast<float>(uv.y()), 0, 5.0f});
      kf.descriptors.push_back(Descriptor{});
    }
    kf.keypoint_landmark = {1, 2};
    s.keyframes.push_back(kf);
  }
  Landmark a, b;
  a.id = 1;
  a.p_A = ahead;
  b.id = 2;
  b.p_A = behind;
  for (KeyframeId k = 1; k <= 2; ++k) {
    a.observations.push_back({k, 0});
    b.observations.push_back({k, 1});
  }
  s.landmarks = {a, b};
  return s;
}

TEST(Scores, EnteringLandmarkOutscoresLeavingOneAtEqualObservations) {
  const Submap s = twoLandmarkWindow();
  ASSERT_EQ(s.validate(), "");
  DistillParams params;
  MotionHint hint;
  hint.valid = true;
  hint.T_A_C = s.keyframes.back().T_A_C;
  hint.T_Cprev_Ccurr = SE3(Mat3::Identity(), Vec3(0.05, 0, 0));  // 1 m/s at 20 Hz
  hint.dt_s = 0.05;
  const LandmarkScores with = computeScores(s, hint, 0, params);
  const LandmarkScores without = computeScores(s, MotionHint{}, 0, params);
  EXPECT_EQ(with.q_s[0], 2.0);
  EXPECT_EQ(with.q_s[1], 2.0);
  // Without attention the landmark behind scores at least as high (it is farther
  // from the optical axis); the predicted poses flip the order.
  EXPECT_GE(without.q_a[1], without.q_a[0] - 1e-9);
  EXPECT_GT(with.q_a[0], with.q_a[1] + 0.5);
  EXPECT_GT(with.q_a[0], without.q_a[0] + 0.5);
  EXPECT_NEAR(with.q_a[1], without.q_a[1], 1e-9);  // leaves the view: no future term
  EXPECT_GT(with.value[0], with.value[1]);
}

TEST(Scores, PredictedPosesFollowConstantVelocity) {
  MotionHint hint;
  hint.valid = true;
  hint.T_A_C = SE3(expSO3(Vec3(0, 0.1, 0)), Vec3(1, 2, 3));
  hint.T_Cprev_Ccurr = SE3(expSO3(Vec3(0, 0.01, 0)), Vec3(0.05, 0, 0));
  hint.dt_s = 0.05;
  const auto poses = predictFuturePoses(hint, 4, 0.2);  // 0.05 s apart = one step each
  ASSERT_EQ(poses.size(), 4u);
  SE3 expected = hint.T_A_C;
  for (const SE3& T : poses) {
    expected = expected * hint.T_Cprev_Ccurr;
    EXPECT_LT((T.translation() - expected.translation()).norm(), 1e-9);
    EXPECT_LT(angularDistance(T, expected), 1e-9);
  }
  EXPECT_TRUE(predictFuturePoses(MotionHint{}, 3, 1.0).empty());
}

TEST(Scores, WeightRuleFollowsLoopsAndRotation) {
  DistillParams params;
  const Submap s = testing::window("MH_01_easy", 40.0).submap;
  const ScoreWeights base = scoreWeights(s, 0, params);
  const ScoreWeights loops = scoreWeights(s, 5, params);
  EXPECT_NEAR(base.alpha + base.beta, 1.0, 1e-12);
  EXPECT_GT(loops.alpha, base.alpha);
  Submap turned = s;  // same window, twice the rotation between keyframes
  for (std::size_t k = 0; k < turned.keyframes.size(); ++k)
    turned.keyframes[k].T_A_C = turned.keyframes[k].T_A_C * SE3(expSO3(Vec3(0, 0.1 * k, 0)), Vec3::Zero());
  EXPECT_GT(scoreWeights(turned, 0, params).beta, base.beta);
  params.adaptive_weights = false;
  params.alpha = 0.3;
  params.beta = 0.1;
  const ScoreWeights fixed = scoreWeights(turned, 7, params);
  EXPECT_NEAR(fixed.alpha, 0.75, 1e-12);
  EXPECT_NEAR(fixed.beta, 0.25, 1e-12);
}

TEST(Scores, StabilityCountsWindowObservations) {
  const SyntheticWindow w = testing::window("V1_01_easy", 20.0);
  const LandmarkScores s = computeScores(w.submap, w.hint, 0, DistillParams{});
  ASSERT_EQ(s.q_s.size(), w.submap.landmarks.size());
  for (std::size_t i = 0; i < s.q_s.size(); ++i) {
    EXPECT_EQ(s.q_s[i], static_cast<double>(w.submap.landmarks[i].observations.size()));
    EXPECT_GE(s.value[i], 0.0);
    EXPECT_LE(s.value[i], 1.0);
    EXPECT_GE(s.q_a[i], 0.0);
  }
}

TEST(Scores, LogDetObjectiveIsMonotoneSubmodular) {
  std::mt19937_64 rng(17);
  std::uniform_int_distribution<int> coin(0, 1);
  const double delta = 1e-3;
  for (int trial = 0; trial < 200; ++trial) {
    const int n = 12;
    std::vector<Mat6> lambdas;
    for (int i = 0; i < n; ++i) {
      Eigen::Matrix<double, 3, 6> W = Eigen::Matrix<double, 3, 6>::Random() * (1 + trial % 5);
      lambdas.push_back(W.transpose() * W);
    }
    std::vector<int> A, B;  // A ⊆ B, e ∉ B
    const int e = n - 1;
    for (int i = 0; i < n - 1; ++i) {
      const bool in_b = coin(rng);
      if (in_b) B.push_back(i);
      if (in_b && coin(rng)) A.push_back(i);
    }
    auto with = [&](std::vector<int> s) { s.push_back(e); return s; };
    const double gA = logDetObjective(lambdas, with(A), delta) - logDetObjective(lambdas, A, delta);
    const double gB = logDetObjective(lambdas, with(B), delta) - logDetObjective(lambdas, B, delta);
    EXPECT_GE(gB, -1e-9) << "monotone";
    EXPECT_GE(gA, gB - 1e-7) << "submodular";
  }
}

}  // namespace
}  // namespace distill
}  // namespace hermes
