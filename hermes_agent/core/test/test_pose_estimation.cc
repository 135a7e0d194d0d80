#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <random>

#include "hermes/agent/pose_estimation.h"

#include "hermes/distill/synthetic_window.h"

using namespace hermes;

namespace {

SE3 randomPose(std::mt19937& rng, double max_angle, double max_t) {
  std::uniform_real_distribution<double> u(-1, 1);
  Vec3 axis(u(rng), u(rng), u(rng));
  return SE3(expSO3(axis.normalized() * max_angle * std::abs(u(rng))),
             Vec3(u(rng), u(rng), u(rng)) * max_t);
}

/// Points seen by a camera at T_C_W, their noisy projections, and a fraction of
/// correspondences replaced by random pixels (outliers).
Correspondences makeScene(std::mt19937& rng, const SE3& T_C_W, const PinholeIntrinsics& K,
                          int n, double noise_px, double outlier_fraction,
                          std::vector<bool>* is_outlier) {
  std::uniform_real_distribution<double> ux(0, K.width), uy(0, K.height), uz(1.5, 8.0),
      u01(0, 1);
  std::normal_distribution<double> noise(0, noise_px);
  Correspondences c;
  const SE3 T_W_C = T_C_W.inverse();
  for (int i = 0; i < n; ++i) {
    const Vec2 uv(ux(rng), uy(rng));
    const double z = uz(rng);
    const Vec3 p_C((uv.x() - K.cx) / K.fx * z, (uv.y() - K.cy) / K.fy * z, z);
    c.p_W.push_back(T_W_C * p_C);
    const bool out = u01(rng) < outlier_fraction;
    is_outlier->push_back(out);
    c.uv.push_back(out ? Vec2(ux(rng), uy(rng)) : uv + Vec2(noise(rng), noise(rng)));
  }
  return c;
}

/// Adds each point's right-image column (baseline b, pixel noise) to c.
void addRightColumns(std::mt19937& rng, const SE3& T_C_W, const PinholeIntrinsics& K, double b,
                     double noise_px, Correspondences* c) {
  std::normal_distribution<double> noise(0, noise_px);
  c->baseline = b;
  for (std::size_t i = 0; i < c->size(); ++i) {
    const Vec3 p = T_C_W * c->p_W[i];
    c->u_right.push_back(K.fx * (p.x() - b) / p.z() + K.cx + noise(rng));
  }
}

/// Left (u, v) and right column of one stereo observation as one 3-vector, for
/// a Ceres reference solve under a single Huber loss (as refinePose weighs them).
struct StereoResidual {
  ReprojectionResidual left;
  double u_right, b, fx, cx, inv_sigma;
  template <class T>
  bool operator()(const T* q, const T* t, T* r) const {
    left(q, t, r);
    const Eigen::Quaternion<T> q_C_W(q[3], q[0], q[1], q[2]);
    const Eigen::Matrix<T, 3, 1> p =
        q_C_W * left_p.cast<T>() + Eigen::Matrix<T, 3, 1>(t[0], t[1], t[2]);
    r[2] = (T(fx) * (p.x() - T(b)) / p.z() + T(cx) - T(u_right)) * T(inv_sigma);
    return true;
  }
  Vec3 left_p;
};

/// Ceres' minimum of the residual blocks `add` puts on (q, t), from init, with
/// tight tolerances: the reference for the hand-written refinement.
SE3 ceresMinimum(const SE3& init, const std::function<void(ceres::Problem&, double*, double*)>& add) {
  const Quat q0 = init.quat();
  double qa[4] = {q0.x(), q0.y(), q0.z(), q0.w()};
  double ta[3] = {init.translation().x(), init.translation().y(), init.translation().z()};
  ceres::Problem::Options po;
  po.manifold_ownership = ceres::TAKE_OWNERSHIP;
  ceres::Problem problem(po);
  problem.AddParameterBlock(qa, 4, new ceres::EigenQuaternionManifold());
  problem.AddParameterBlock(ta, 3);
  add(problem, qa, ta);
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = 100;
  so.function_tolerance = 1e-12;
  so.parameter_tolerance = 1e-12;
  so.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  return SE3(Quat(qa[3], qa[0], qa[1], qa[2]), Vec3(ta[0], ta[1], ta[2]));
}

}  // namespace

TEST(PoseEstimation, AutodiffJacobianMatchesCentralDifferences) {
  std::mt19937 rng(3);
  const PinholeIntrinsics K = distill::eurocCam0Intrinsics();
  for (int trial = 0; trial < 20; ++trial) {
    const SE3 T = randomPose(rng, 0.5, 0.3);
    const Vec3 p_W = T.inverse() * Vec3(0.3 * trial / 20.0 - 0.1, -0.2, 2.0 + 0.1 * trial);
    const Vec2 uv(300, 200);
    std::unique_ptr<ceres::CostFunction> cost(ReprojectionResidual::create(uv, p_W, K, 1.3));
    double q[4] = {T.quat().x(), T.quat().y(), T.quat().z(), T.quat().w()};
    double t[3] = {T.translation().x(), T.translation().y(), T.translation().z()};
    double* params[2] = {q, t};
    double r[2], Jq[8], Jt[6];
    double* jac[2] = {Jq, Jt};
    ASSERT_TRUE(cost->Evaluate(params, r, jac));
    const double h = 1e-6;
    ReprojectionResidual f(uv, p_W, K, 1.3);
    for (int block = 0; block < 2; ++block) {
      const int dim = block == 0 ? 4 : 3;
      double* x = block == 0 ? q : t;
      for (int k = 0; k < dim; ++k) {
        const double x0 = x[k];
        double rp[2], rm[2];
        x[k] = x0 + h;
        f(q, t, rp);
        x[k] = x0 - h;
        f(q, t, rm);
        x[k] = x0;
        for (int row = 0; row < 2; ++row) {
          const double numeric = (rp[row] - rm[row]) / (2 * h);
          const double analytic = jac[block][row * dim + k];
          EXPECT_NEAR(analytic, numeric, 1e-5 * std::max(1.0, std::abs(numeric)))
              << "block " << block << " param " << k << " row " << row;
        }
      }
    }
  }
}

TEST(PoseEstimation, PnpRansacAndRefinementWithOutliers) {
  std::mt19937 rng(7);
  const PinholeIntrinsics K = distill::eurocCam0Intrinsics();
  double worst_t = 0, worst_r = 0;
  for (int trial = 0; trial < 5; ++trial) {
    const SE3 T_C_W = randomPose(rng, 0.6, 1.0);
    std::vector<bool> is_out;
    Correspondences c = makeScene(rng, T_C_W, K, 300, 0.8, 0.3, &is_out);
    auto est = estimatePose(c, K, PoseEstimationParams());
    ASSERT_TRUE(est.ok()) << est.error();
    worst_t = std::max(worst_t, translationalDistance(est->T_C_W, T_C_W));
    worst_r = std::max(worst_r, angularDistance(est->T_C_W, T_C_W) * 180 / M_PI);
    int wrong = 0;
    for (size_t i = 0; i < c.size(); ++i) wrong += est->inlier[i] && is_out[i];
    EXPECT_LE(wrong, 3);  // a random pixel may land within the gate by chance
    EXPECT_LT(est->rms_px, 1.5);
  }
  std::printf("PnP+refinement worst error over 5 trials: %.4f m, %.4f deg\n", worst_t, worst_r);
  EXPECT_LT(worst_t, 0.01);
  EXPECT_LT(worst_r, 0.1);
}

TEST(PoseEstimation, RefinementFromPredictionRejectsOutliers) {
  std::mt19937 rng(11);
  const PinholeIntrinsics K = distill::eurocCam0Intrinsics();
  const SE3 T_C_W = randomPose(rng, 0.4, 0.5);
  std::vector<bool> is_out;
  Correspondences c = makeScene(rng, T_C_W, K, 200, 0.5, 0.3, &is_out);
  // Constant-velocity-like prediction: 2 cm and 1 deg off.
  const SE3 pred = SE3::exp((Vec6() << 0.02, -0.01, 0.01, 0.01, 0.012, -0.008).finished()) * T_C_W;
  auto est = refinePose(c, K, pred, PoseEstimationParams());
  ASSERT_TRUE(est.ok()) << est.error();
  EXPECT_LT(translationalDistance(est->T_C_W, T_C_W), 0.01);
  EXPECT_LT(angularDistance(est->T_C_W, T_C_W) * 180 / M_PI, 0.1);
  int missed = 0;
  for (size_t i = 0; i < c.size(); ++i) missed += !est->inlier[i] && !is_out[i];
  EXPECT_LT(missed, 5);
}

TEST(PoseEstimation, UntrustedObservationsCannotPullThePose) {
  // 120 static points, and 240 on an object that moved 6 cm since its points
  // were mapped: refined from the true pose, all of them together settle on
  // the object; with only the static ones trusted the pose stays true and the
  // object's points are outliers.
  std::mt19937 rng(5);
  const PinholeIntrinsics K = distill::eurocCam0Intrinsics();
  const SE3 T_C_W = randomPose(rng, 0.3, 0.5);
  std::vector<bool> is_out;
  Correspondences c = makeScene(rng, T_C_W, K, 360, 0.5, 0.0, &is_out);
  std::vector<bool> trusted(c.size(), true);
  const Vec3 moved(0.06, 0.0, 0.0);
  for (std::size_t i = 120; i < c.size(); ++i) {
    c.p_W[i] -= T_C_W.inverse().rotation() * moved;  // mapped where the object was
    trusted[i] = false;
  }
  auto all = refinePose(c, K, T_C_W, PoseEstimationParams());
  ASSERT_TRUE(all.ok()) << all.error();
  EXPECT_GT(translationalDistance(all->T_C_W, T_C_W), 0.03);
  auto est = refinePose(c, K, T_C_W, PoseEstimationParams(), nullptr, &trusted);
  ASSERT_TRUE(est.ok()) << est.error();
  EXPECT_LT(translationalDistance(est->T_C_W, T_C_W), 0.005);
  int static_in = 0, object_in = 0;
  for (std::size_t i = 0; i < c.size(); ++i) (i < 120 ? static_in : object_in) += est->inlier[i];
  EXPECT_GT(static_in, 110);
  EXPECT_LT(object_in, 12);
  std::vector<bool> wrong_length(3, true);
  EXPECT_FALSE(refinePose(c, K, T_C_W, PoseEstimationParams(), nullptr, &wrong_length).ok());
}

TEST(PoseEstimation, RefinementReachesTheCeresOptimumOfTheSameRobustCost) {
  // One round over every observation (30 % outliers, so the Huber tails matter):
  // the hand-written Levenberg-Marquardt and Ceres on ReprojectionResidual +
  // HuberLoss must land on the same minimum.
  std::mt19937 rng(5);
  const PinholeIntrinsics K = distill::eurocCam0Intrinsics();
  for (int trial = 0; trial < 5; ++trial) {
    const SE3 T_C_W = randomPose(rng, 0.5, 0.5);
    std::vector<bool> is_out;
    Correspondences c = makeScene(rng, T_C_W, K, 150, 0.7, 0.3, &is_out);
    for (std::size_t i = 0; i < c.size(); ++i) c.sigma_px.push_back(i % 3 == 0 ? 1.44 : 1.0);
    const SE3 init =
        SE3::exp((Vec6() << 0.03, -0.02, 0.01, 0.01, -0.015, 0.02).finished()) * T_C_W;
    PoseEstimationParams p;
    p.refine_rounds = 1;
    p.iterations_per_round = 100;
    auto est = refinePose(c, K, init, p);
    ASSERT_TRUE(est.ok()) << est.error();

    const SE3 ref = ceresMinimum(init, [&](ceres::Problem& problem, double* qa, double* ta) {
      for (std::size_t i = 0; i < c.size(); ++i)
        problem.AddResidualBlock(ReprojectionResidual::create(c.uv[i], c.p_W[i], K, c.sigma_px[i]),
                                 new ceres::HuberLoss(p.huber_px), qa, ta);
    });
    EXPECT_LT(translationalDistance(est->T_C_W, ref), 1e-6) << "trial " << trial;
    EXPECT_LT(angularDistance(est->T_C_W, ref), 1e-7) << "trial " << trial;
  }
}

TEST(PoseEstimation, BadInputIsAnError) {
  const PinholeIntrinsics K = distill::eurocCam0Intrinsics();
  Correspondences c;
  EXPECT_FALSE(estimatePose(c, K, PoseEstimationParams()).ok());
  std::mt19937 rng(1);
  std::vector<bool> is_out;
  c = makeScene(rng, SE3(), K, 50, 0.5, 0.0, &is_out);
  c.uv.pop_back();
  EXPECT_FALSE(estimatePose(c, K, PoseEstimationParams()).ok());
  c.uv.push_back(Vec2(std::nan(""), 1));
  auto e = refinePose(c, K, SE3(), PoseEstimationParams());
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.error().find("49"), std::string::npos);
  // All outliers: RANSAC cannot find a consensus.
  c = makeScene(rng, SE3(), K, 60, 0.5, 1.0, &is_out);
  EXPECT_FALSE(estimatePose(c, K, PoseEstimationParams()).ok());
}

TEST(PoseEstimation, StereoRefinementReachesTheCeresOptimumOfTheSameRobustCost) {
  // As above with a right-image column on two thirds of the observations: the
  // hand-written Jacobian of the third row must lead to Ceres' minimum.
  std::mt19937 rng(21);
  const PinholeIntrinsics K = distill::eurocCam0Intrinsics();
  const double b = 0.11;
  for (int trial = 0; trial < 5; ++trial) {
    const SE3 T_C_W = randomPose(rng, 0.5, 0.5);
    std::vector<bool> is_out;
    Correspondences c = makeScene(rng, T_C_W, K, 150, 0.7, 0.3, &is_out);
    addRightColumns(rng, T_C_W, K, b, 0.7, &c);
    for (std::size_t i = 0; i < c.size(); ++i) {
      c.sigma_px.push_back(i % 3 == 0 ? 1.44 : 1.0);
      if (i % 3 == 1) c.u_right[i] = -1;  // no stereo match
    }
    const SE3 init =
        SE3::exp((Vec6() << 0.03, -0.02, 0.01, 0.01, -0.015, 0.02).finished()) * T_C_W;
    PoseEstimationParams p;
    p.refine_rounds = 1;
    p.iterations_per_round = 100;
    p.stereo_sigma_scale = 1.5;
    auto est = refinePose(c, K, init, p);
    ASSERT_TRUE(est.ok()) << est.error();

    const SE3 ref = ceresMinimum(init, [&](ceres::Problem& problem, double* qa, double* ta) {
      for (std::size_t i = 0; i < c.size(); ++i) {
        ceres::LossFunction* loss = new ceres::HuberLoss(p.huber_px);
        if (c.u_right[i] < 0) {
          problem.AddResidualBlock(
              ReprojectionResidual::create(c.uv[i], c.p_W[i], K, c.sigma_px[i]), loss, qa, ta);
          continue;
        }
        auto* f = new StereoResidual{ReprojectionResidual(c.uv[i], c.p_W[i], K, c.sigma_px[i]),
                                     c.u_right[i], b, K.fx, K.cx,
                                     1.0 / (c.sigma_px[i] * p.stereo_sigma_scale), c.p_W[i]};
        problem.AddResidualBlock(new ceres::AutoDiffCostFunction<StereoResidual, 3, 4, 3>(f), loss,
                                 qa, ta);
      }
    });
    EXPECT_LT(translationalDistance(est->T_C_W, ref), 1e-6) << "trial " << trial;
    EXPECT_LT(angularDistance(est->T_C_W, ref), 1e-7) << "trial " << trial;
  }
}

TEST(PoseEstimation, RightColumnMakesThePoseMoreAccurate) {
  // 20 points 1-6 m away in an 80 x 80 px patch (a textured spot seen through a
  // narrow view), 1 px noise on every column, 100 poses refined from the truth:
  // the right column's depth makes the translation and the rotation better on
  // average (measured 1.68 -> 1.31 cm, 0.37 -> 0.29 deg). The data's right
  // column is as noisy as the left one, so it is weighed as such (scale 1).
  const PinholeIntrinsics K = distill::eurocCam0Intrinsics();
  std::mt19937 rng(8);
  std::uniform_real_distribution<double> ux(K.cx - 40, K.cx + 40), uy(K.cy - 40, K.cy + 40),
      uz(1.0, 6.0);
  std::normal_distribution<double> noise(0, 1.0);
  PoseEstimationParams mono, stereo;
  mono.stereo_residual = false;
  stereo.stereo_sigma_scale = 1;
  double t_mono = 0, t_stereo = 0, r_mono = 0, r_stereo = 0;
  for (int trial = 0; trial < 100; ++trial) {
    const SE3 T_C_W = randomPose(rng, 0.3, 0.5);
    Correspondences c;
    for (int i = 0; i < 20; ++i) {
      const Vec2 uv(ux(rng), uy(rng));
      const double z = uz(rng);
      c.p_W.push_back(T_C_W.inverse() *
                      Vec3((uv.x() - K.cx) / K.fx * z, (uv.y() - K.cy) / K.fy * z, z));
      c.uv.push_back(uv + Vec2(noise(rng), noise(rng)));
    }
    addRightColumns(rng, T_C_W, K, 0.11, 1.0, &c);
    auto a = refinePose(c, K, T_C_W, mono);
    auto b = refinePose(c, K, T_C_W, stereo);
    ASSERT_TRUE(a.ok() && b.ok()) << "trial " << trial;
    t_mono += translationalDistance(a->T_C_W, T_C_W) / 100;
    t_stereo += translationalDistance(b->T_C_W, T_C_W) / 100;
    r_mono += angularDistance(a->T_C_W, T_C_W) * 180 / M_PI / 100;
    r_stereo += angularDistance(b->T_C_W, T_C_W) * 180 / M_PI / 100;
  }
  std::printf("narrow view, mean error: left only %.2f cm %.3f deg, with the right column "
              "%.2f cm %.3f deg\n", 100 * t_mono, r_mono, 100 * t_stereo, r_stereo);
  EXPECT_LT(t_stereo, 0.9 * t_mono);
  EXPECT_LT(r_stereo, 0.9 * r_mono);
}

TEST(PoseEstimation, AWrongRightColumnMakesAnOutlier) {
  std::mt19937 rng(9);
  const PinholeIntrinsics K = distill::eurocCam0Intrinsics();
  const SE3 T_C_W = randomPose(rng, 0.3, 0.3);
  std::vector<bool> is_out;
  Correspondences c = makeScene(rng, T_C_W, K, 100, 0.3, 0.0, &is_out);
  addRightColumns(rng, T_C_W, K, 0.11, 0.3, &c);
  c.u_right[7] -= 12;  // a wrong stereo match: the left observation is right
  auto with = refinePose(c, K, T_C_W, PoseEstimationParams());
  PoseEstimationParams mono;
  mono.stereo_residual = false;
  auto without = refinePose(c, K, T_C_W, mono);
  ASSERT_TRUE(with.ok() && without.ok());
  EXPECT_FALSE(with->inlier[7]);
  EXPECT_TRUE(without->inlier[7]);
  // Right columns without a baseline are refused.
  c.baseline = 0;
  EXPECT_FALSE(refinePose(c, K, T_C_W, PoseEstimationParams()).ok());
}
