#include <gtest/gtest.h>

#include <random>

#include <ceres/ceres.h>

#include "hermes/agent/bundle_adjustment.h"

using namespace hermes;

namespace {

PinholeIntrinsics testK() {
  PinholeIntrinsics K;
  K.fx = K.fy = 436.0;
  K.cx = 375.5;
  K.cy = 239.5;
  K.width = 752;
  K.height = 480;
  return K;
}

/// Compares the autodiff Jacobian of `cost` (blocks q4, t3, p3) with central
/// differences on the raw parameters; returns the largest absolute difference.
double jacobianGap(const ceres::CostFunction& cost, int nres, std::array<double, 4> q,
                   std::array<double, 3> t, std::array<double, 3> p) {
  std::vector<double*> blocks = {q.data(), t.data(), p.data()};
  const int sizes[3] = {4, 3, 3};
  std::vector<std::vector<double>> J(3);
  std::vector<double*> jp(3);
  for (int b = 0; b < 3; ++b) {
    J[b].assign(nres * sizes[b], 0);
    jp[b] = J[b].data();
  }
  std::vector<double> r(nres), rp(nres), rm(nres);
  EXPECT_TRUE(cost.Evaluate(blocks.data(), r.data(), jp.data()));
  double gap = 0;
  const double h = 1e-6;
  for (int b = 0; b < 3; ++b)
    for (int j = 0; j < sizes[b]; ++j) {
      const double x = blocks[b][j];
      blocks[b][j] = x + h;
      cost.Evaluate(blocks.data(), rp.data(), nullptr);
      blocks[b][j] = x - h;
      cost.Evaluate(blocks.data(), rm.data(), nullptr);
      blocks[b][j] = x;
      for (int i = 0; i < nres; ++i)
        gap = std::max(gap, std::abs((rp[i] - rm[i]) / (2 * h) - J[b][i * sizes[b] + j]));
    }
  return gap;
}

}  // namespace

TEST(BundleAdjustment, AutodiffJacobianMatchesCentralDifferences) {
  const PinholeIntrinsics K = testK();
  const Quat qr = Quat(Eigen::AngleAxisd(0.3, Vec3(0.2, 1, -0.4).normalized()));
  const std::array<double, 4> q = {qr.x(), qr.y(), qr.z(), qr.w()};
  const std::array<double, 3> t = {0.1, -0.2, 0.5}, p = {0.4, 0.3, 3.0};
  ceres::AutoDiffCostFunction<MonoReprojectionError, 2, 4, 3, 3> mono(
      new MonoReprojectionError(K, Vec2(400, 250), 1.5));
  ceres::AutoDiffCostFunction<StereoReprojectionError, 3, 4, 3, 3> stereo(
      new StereoReprojectionError(K, 0.11, Vec2(400, 250), 380, 1.2));
  EXPECT_LT(jacobianGap(mono, 2, q, t, p), 1e-5);
  EXPECT_LT(jacobianGap(stereo, 3, q, t, p), 1e-5);
  // The rotation in the functor equals Eigen's.
  double pc[3];
  MonoReprojectionError::rotate(q.data(), t.data(), p.data(), pc);
  const Vec3 ref = qr * Vec3(p[0], p[1], p[2]) + Vec3(t[0], t[1], t[2]);
  EXPECT_NEAR((Vec3(pc[0], pc[1], pc[2]) - ref).norm(), 0, 1e-12);
}

namespace {

struct Synthetic {
  BaProblem truth, noisy;
};

/// Six cameras moving sideways in front of a 3-D point cloud; the first two
/// poses are fixed. Stereo measurements for every second point.
Synthetic makeProblem(unsigned seed, double pose_noise, double point_noise, double pixel_noise) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0, 1);
  std::uniform_real_distribution<double> uni(-1, 1);
  Synthetic s;
  BaProblem& pb = s.truth;
  pb.K = testK();
  pb.baseline = 0.11;
  for (int i = 0; i < 6; ++i) {
    const SE3 T_W_C(expSO3(Vec3(0.02 * i, 0.05 * std::sin(i), 0)), Vec3(0.2 * i, 0.03 * i, 0));
    pb.T_C_W.push_back(T_W_C.inverse());
    pb.pose_fixed.push_back(i < 2);
  }
  for (int j = 0; j < 300; ++j) pb.p_W.push_back(Vec3(2.5 * uni(rng) + 0.5, 1.5 * uni(rng), 4 + 2 * uni(rng)));
  s.noisy = pb;
  for (int i = 0; i < 6; ++i)
    for (int j = 0; j < 300; ++j) {
      const Vec3 pc = pb.T_C_W[i] * pb.p_W[j];
      const Vec2 uv = pb.K.project(pc);
      if (!pb.K.inImage(uv, 5)) continue;
      BaObservation o;
      o.pose = i;
      o.point = j;
      o.uv = uv + pixel_noise * Vec2(n(rng), n(rng));
      if (j % 2 == 0) o.u_right = uv.x() - pb.K.fx * pb.baseline / pc.z() + pixel_noise * n(rng);
      pb.observations.push_back(o);
    }
  s.noisy.observations = pb.observations;
  for (int i = 2; i < 6; ++i) {
    Vec6 xi;
    for (int k = 0; k < 6; ++k) xi[k] = n(rng) * (k < 3 ? pose_noise : pose_noise / 2);
    s.noisy.T_C_W[i] = SE3::exp(xi) * pb.T_C_W[i];
  }
  for (auto& p : s.noisy.p_W) p += point_noise * Vec3(n(rng), n(rng), n(rng));
  return s;
}

double poseError(const BaProblem& a, const BaProblem& b) {
  double worst = 0;
  for (std::size_t i = 0; i < a.T_C_W.size(); ++i)
    worst = std::max(worst, (a.T_C_W[i].inverse().translation() -
                             b.T_C_W[i].inverse().translation()).norm());
  return worst;
}

/// RMSE over the points seen at least twice (the others are unconstrained).
double pointRmse(const BaProblem& a, const BaProblem& b) {
  std::vector<int> seen(a.p_W.size(), 0);
  for (const auto& o : a.observations) ++seen[o.point];
  double sq = 0;
  int n = 0;
  for (std::size_t j = 0; j < a.p_W.size(); ++j)
    if (seen[j] >= 2) {
      sq += (a.p_W[j] - b.p_W[j]).squaredNorm();
      ++n;
    }
  return std::sqrt(sq / std::max(n, 1));
}

}  // namespace

TEST(BundleAdjustment, RemovesInjectedNoise) {
  Synthetic s = makeProblem(7, 0.05, 0.1, 0.5);
  const double pose0 = poseError(s.noisy, s.truth), point0 = pointRmse(s.noisy, s.truth);
  BundleAdjustmentParams params;
  params.max_iterations = 20;
  auto r = solveBundleAdjustment(&s.noisy, params);
  ASSERT_TRUE(r.ok()) << r.error();
  const double pose1 = poseError(s.noisy, s.truth), point1 = pointRmse(s.noisy, s.truth);
  EXPECT_GT(pose0, 0.03);
  EXPECT_LT(pose1, 0.01) << "before " << pose0;
  EXPECT_LT(point1, 0.03) << "before " << point0;
  EXPECT_LT(r->final_cost, 0.01 * r->initial_cost);
  EXPECT_LT(r->num_outliers, int(s.noisy.observations.size()) / 50);
  for (int i = 0; i < 2; ++i)  // fixed poses untouched
    EXPECT_NEAR((s.noisy.T_C_W[i].translation() - s.truth.T_C_W[i].translation()).norm(), 0, 1e-12);
}

TEST(BundleAdjustment, FlagsGrossOutliers) {
  Synthetic s = makeProblem(3, 0.0, 0.0, 0.3);
  for (std::size_t k = 0; k < s.noisy.observations.size(); k += 37) s.noisy.observations[k].uv += Vec2(25, -18);
  auto r = solveBundleAdjustment(&s.noisy, BundleAdjustmentParams());
  ASSERT_TRUE(r.ok()) << r.error();
  int caught = 0, corrupted = 0;
  for (std::size_t k = 0; k < s.noisy.observations.size(); k += 37) {
    ++corrupted;
    caught += r->outlier[k];
  }
  EXPECT_EQ(caught, corrupted);
  EXPECT_LT(poseError(s.noisy, s.truth), 0.01);  // Huber keeps the solution
}

TEST(BundleAdjustment, RejectsBadInput) {
  Synthetic s = makeProblem(1, 0, 0, 0);
  BaProblem pb = s.noisy;
  pb.pose_fixed.assign(pb.T_C_W.size(), false);
  EXPECT_FALSE(solveBundleAdjustment(&pb, BundleAdjustmentParams()).ok());
  pb = s.noisy;
  pb.observations[0].point = 100000;
  auto r = solveBundleAdjustment(&pb, BundleAdjustmentParams());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().find("observation 0"), std::string::npos);
  pb = s.noisy;
  pb.p_W[3].x() = std::nan("");
  EXPECT_FALSE(solveBundleAdjustment(&pb, BundleAdjustmentParams()).ok());
  pb = s.noisy;
  pb.baseline = 0;
  EXPECT_FALSE(solveBundleAdjustment(&pb, BundleAdjustmentParams()).ok());
}
