// Odometry noise model: variance linear in distance and rotation, quality
// weights, composition of edge covariances (checked against numerical
// differentiation), parameter checks.
#include <gtest/gtest.h>

#include <random>

#include "hermes/core/odometry_noise.h"

using namespace hermes;

namespace {

SE3 straight(double metres) { return SE3(Quat::Identity(), Vec3(metres, 0, 0)); }

}  // namespace

TEST(OdometryNoise, VarianceGrowsLinearlyWithDistanceAndRotation) {
  OdometryNoiseParams p;
  const double f = p.trans_floor_m * p.trans_floor_m;
  const Mat6 c1 = odometryCovariance(straight(1.0), -1, false, p);
  const Mat6 c4 = odometryCovariance(straight(4.0), -1, false, p);
  EXPECT_NEAR((c4(0, 0) - f) / (c1(0, 0) - f), 4.0, 1e-9);
  EXPECT_NEAR(c1(0, 0), f + p.trans_per_sqrt_m * p.trans_per_sqrt_m, 1e-12);
  EXPECT_DOUBLE_EQ(c1(0, 0), c1(2, 2));
  EXPECT_NEAR(c1(3, 3), p.rot_floor_rad * p.rot_floor_rad + p.rot_per_sqrt_m * p.rot_per_sqrt_m, 1e-12);
  const SE3 turn(Quat(Eigen::AngleAxisd(0.5, Vec3::UnitZ())), Vec3::Zero());
  const Mat6 ct = odometryCovariance(turn, -1, false, p);
  EXPECT_NEAR(ct(5, 5), p.rot_floor_rad * p.rot_floor_rad + 0.5 * p.rot_per_sqrt_rad * p.rot_per_sqrt_rad, 1e-12);
  EXPECT_EQ(Mat6(c1 - c1.diagonal().asDiagonal().toDenseMatrix()).norm(), 0.0);  // diagonal
  const Mat6 info = odometryInformation(straight(1.0), -1, false, p);
  EXPECT_TRUE((info * c1).isApprox(Mat6::Identity(), 1e-12));
}

TEST(OdometryNoise, QualityWeightsAndLostFrames) {
  OdometryNoiseParams p;
  const Mat6 full = odometryCovariance(straight(0.3), p.shared_ref, false, p);
  EXPECT_TRUE(full.isApprox(odometryCovariance(straight(0.3), 10 * p.shared_ref, false, p)));
  EXPECT_TRUE(full.isApprox(odometryCovariance(straight(0.3), -1, false, p)));  // unknown
  const Mat6 half = odometryCovariance(straight(0.3), p.shared_ref / 2, false, p);
  EXPECT_NEAR(half(0, 0) / full(0, 0), 2.0, 1e-9);
  const Mat6 none = odometryCovariance(straight(0.3), 0, false, p);
  EXPECT_NEAR(none(0, 0) / full(0, 0), 1.0 / p.min_weight, 1e-9);  // bounded, never singular
  const Mat6 lost = odometryCovariance(straight(0.3), p.shared_ref, true, p);
  EXPECT_NEAR(lost(4, 4) / full(4, 4), p.lost_inflation, 1e-9);
}

TEST(OdometryNoise, SplittingAStraightEdgeKeepsItsVariance) {
  OdometryNoiseParams p;
  p.trans_floor_m = 1e-9;
  p.rot_floor_rad = 1e-9;
  p.rot_per_sqrt_m = 1e-9;  // no rotation noise: translation variances simply add
  std::vector<RelativePoseCov> halves(2);
  for (auto& h : halves) h = {straight(0.5), odometryCovariance(straight(0.5), -1, false, p)};
  const RelativePoseCov c = composeEdges(halves);
  EXPECT_LT(translationalDistance(c.T, straight(1.0)), 1e-12);
  EXPECT_NEAR(c.covariance(0, 0), odometryCovariance(straight(1.0), -1, false, p)(0, 0), 1e-12);
}

TEST(OdometryNoise, CompositionMatchesNumericalJacobians) {
  std::mt19937 rng(5);
  std::normal_distribution<double> n(0, 1);
  auto randomPose = [&] {
    Vec6 xi;
    for (int i = 0; i < 6; ++i) xi(i) = n(rng) * (i < 3 ? 0.7 : 0.4);
    return SE3::exp(xi);
  };
  std::vector<RelativePoseCov> edges(4);
  for (auto& e : edges) {
    e.T = randomPose();
    Mat6 A = Mat6::Random();
    e.covariance = 1e-3 * (A * A.transpose() + Mat6::Identity());
  }
  const RelativePoseCov c = composeEdges(edges);
  SE3 T;
  for (const auto& e : edges) T = T * e.T;
  EXPECT_LT(translationalDistance(c.T, T), 1e-12);
  EXPECT_LT(angularDistance(c.T, T), 1e-12);
  // xi_total = sum_k J_k xi_k with J_k from central differences of
  // log(T^-1 * prod_i E_i exp(xi_i [i == k])).
  Mat6 expected = Mat6::Zero();
  const double h = 1e-6;
  for (std::size_t k = 0; k < edges.size(); ++k) {
    Mat6 J;
    for (int d = 0; d < 6; ++d) {
      auto perturbed = [&](double s) {
        SE3 P;
        for (std::size_t i = 0; i < edges.size(); ++i) {
          Vec6 xi = Vec6::Zero();
          if (i == k) xi(d) = s;
          P = P * edges[i].T * SE3::exp(xi);
        }
        return (T.inverse() * P).log();
      };
      J.col(d) = (perturbed(h) - perturbed(-h)) / (2 * h);
    }
    expected += J * edges[k].covariance * J.transpose();
  }
  EXPECT_TRUE(c.covariance.isApprox(expected, 1e-5)) << c.covariance << "\n\n" << expected;
  EXPECT_TRUE(composeEdges({}).covariance.isZero());
}

TEST(OdometryNoise, InvertedCovarianceAndSpdInverse) {
  const SE3 T = SE3::exp((Vec6() << 0.3, -0.2, 0.5, 0.1, 0.2, -0.3).finished());
  Mat6 A = Mat6::Random();
  const Mat6 cov = A * A.transpose() + Mat6::Identity();
  // Round trip: inverting twice gives the covariance back.
  EXPECT_TRUE(invertedCovariance(T.inverse(), invertedCovariance(T, cov)).isApprox(cov, 1e-9));
  auto inv = invertSpd(cov);
  ASSERT_TRUE(inv.ok());
  EXPECT_TRUE((*inv * cov).isApprox(Mat6::Identity(), 1e-9));
  EXPECT_FALSE(invertSpd(-cov).ok());
  Mat6 bad = cov;
  bad(0, 0) = std::nan("");
  EXPECT_FALSE(invertSpd(bad).ok());
}

TEST(OdometryNoise, ParamsReadValidateAndRoundTrip) {
  auto c = Config::fromString("odometry:\n  trans_per_sqrt_m: 0.02\n  shared_ref: 30\n", "test");
  ASSERT_TRUE(c.ok());
  OdometryNoiseParams p;
  ASSERT_TRUE(p.read(*c).ok());
  EXPECT_DOUBLE_EQ(p.trans_per_sqrt_m, 0.02);
  EXPECT_EQ(p.shared_ref, 30);
  ConfigWriter w;
  p.write(&w);
  auto back = Config::fromString(w.yaml(), "written");
  ASSERT_TRUE(back.ok());
  OdometryNoiseParams q;
  ASSERT_TRUE(q.read(*back).ok());
  EXPECT_DOUBLE_EQ(q.trans_per_sqrt_m, 0.02);
  auto bad = Config::fromString("odometry:\n  rot_floor_rad: 0\n", "bad.yaml");
  ASSERT_TRUE(bad.ok());
  Status s = OdometryNoiseParams().read(*bad);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().find("rot_floor_rad"), std::string::npos) << s.error();
  auto neg = Config::fromString("odometry:\n  rot_per_sqrt_m: -1\n", "neg.yaml");
  EXPECT_FALSE(OdometryNoiseParams().read(*neg).ok());
}
