// Pose graph: residual Jacobian check, two-agent drift correction, robust loss.
#include <gtest/gtest.h>

#include <random>

#include "hermes/server/pose_graph.h"

namespace hermes {
namespace server {
namespace {

constexpr double kDeg = M_PI / 180.0;

Vec6 randomTangent(std::mt19937& rng, double sigma_t, double sigma_r) {
  std::normal_distribution<double> n(0, 1);
  Vec6 xi;
  xi << sigma_t * n(rng), sigma_t * n(rng), sigma_t * n(rng), sigma_r * n(rng), sigma_r * n(rng),
      sigma_r * n(rng);
  return xi;
}

Mat6 diagInformation(double sigma_t, double sigma_r) {
  Vec6 d;
  d << Vec3::Constant(1 / (sigma_t * sigma_t)), Vec3::Constant(1 / (sigma_r * sigma_r));
  return d.asDiagonal();
}

TEST(PoseGraph, AutodiffJacobianMatchesCentralDifferences) {
  std::mt19937 rng(3);
  for (int trial = 0; trial < 5; ++trial) {
    const SE3 Ta = SE3::exp(randomTangent(rng, 2.0, 1.0));
    const SE3 Tb = SE3::exp(randomTangent(rng, 2.0, 1.0));
    const SE3 meas = Ta.inverse() * Tb * SE3::exp(randomTangent(rng, 0.2, 0.1));
    Mat6 A = Mat6::Random();
    const Mat6 info = A * A.transpose() + Mat6::Identity();
    const Mat6 L = *sqrtInformation(info);
    std::unique_ptr<ceres::CostFunction> cost(RelativePoseError::create(meas, L));
    const RelativePoseError functor(meas, L);

    std::vector<std::vector<double>> x = {
        {Ta.quat().x(), Ta.quat().y(), Ta.quat().z(), Ta.quat().w()},
        {Ta.translation().x(), Ta.translation().y(), Ta.translation().z()},
        {Tb.quat().x(), Tb.quat().y(), Tb.quat().z(), Tb.quat().w()},
        {Tb.translation().x(), Tb.translation().y(), Tb.translation().z()}};
    const double* params[4] = {x[0].data(), x[1].data(), x[2].data(), x[3].data()};
    double r[6];
    std::vector<std::vector<double>> J = {std::vector<double>(24), std::vector<double>(18),
                                          std::vector<double>(24), std::vector<double>(18)};
    double* jac[4] = {J[0].data(), J[1].data(), J[2].data(), J[3].data()};
    ASSERT_TRUE(cost->Evaluate(params, r, jac));

    // The residual at the measured-consistent point is whitened error: check value.
    const Vec6 e_true = [&] {
      const SE3 err = meas.inverse() * Ta.inverse() * Tb;
      Vec6 e;
      e.head<3>() = err.translation();
      const Quat q = err.quat().w() < 0 ? Quat(-err.quat().coeffs()) : err.quat();
      e.tail<3>() = 2 * q.vec();
      return e;
    }();
    EXPECT_LT((Eigen::Map<Vec6>(r) - L * e_true).norm(), 1e-9);

    const double h = 1e-6;
    double max_err = 0;
    for (int b = 0; b < 4; ++b) {
      for (std::size_t k = 0; k < x[b].size(); ++k) {
        auto xp = x, xm = x;
        xp[b][k] += h;
        xm[b][k] -= h;
        double rp[6], rm[6];
        functor(xp[0].data(), xp[1].data(), xp[2].data(), xp[3].data(), rp);
        functor(xm[0].data(), xm[1].data(), xm[2].data(), xm[3].data(), rm);
        for (int i = 0; i < 6; ++i) {
          const double num = (rp[i] - rm[i]) / (2 * h);
          const double ad = J[b][i * x[b].size() + k];
          max_err = std::max(max_err, std::abs(num - ad) / std::max(1.0, std::abs(num)));
        }
      }
    }
    EXPECT_LT(max_err, 1e-5) << "trial " << trial;
  }
}

/// Two agents on overlapping circles; odometry with a yaw bias (drift).
struct Graph {
  std::map<KeyframeKey, SE3> truth;
  std::vector<std::vector<KeyframeKey>> keys;  // per agent, in order
};

Graph makeTruth(int n_per_agent) {
  Graph g;
  g.keys.resize(2);
  for (std::uint32_t a = 0; a < 2; ++a) {
    const Vec3 center(a == 0 ? 0.0 : 3.0, 0, 0);
    for (int i = 0; i < n_per_agent; ++i) {
      const double th = 2 * M_PI * 1.2 * i / n_per_agent + (a == 0 ? 0 : M_PI);
      const Vec3 p = center + Vec3(6 * std::cos(th), 6 * std::sin(th), 0.3 * std::sin(3 * th));
      const Mat3 R = expSO3(Vec3(0, 0, th + M_PI / 2));
      const KeyframeKey key{a, 0, static_cast<KeyframeId>(i)};
      g.truth[key] = SE3(R, p);
      g.keys[a].push_back(key);
    }
  }
  return g;
}

double ate(const std::map<KeyframeKey, SE3>& est, const std::map<KeyframeKey, SE3>& truth) {
  double sum = 0;
  for (const auto& [k, T] : truth) sum += (est.at(k).translation() - T.translation()).squaredNorm();
  return std::sqrt(sum / truth.size());
}

struct LoopSpec {
  KeyframeKey a, b;
  SE3 T_a_b;
};

/// Builds the graph: dead-reckoned initial poses, agent 1 placed with a wrong T_W_A.
PoseGraph buildGraph(const Graph& g, const PoseGraphParams& params, const std::vector<LoopSpec>& loops,
                     std::mt19937& rng, std::map<KeyframeKey, SE3>* initial) {
  PoseGraph pg(params);
  const double st = 0.01, sr = 0.2 * kDeg;
  const SE3 bias = SE3::exp((Vec6() << 0.002, 0, 0, 0.0, 0.0, 0.15 * kDeg).finished());
  for (std::uint32_t a = 0; a < 2; ++a) {
    const auto& keys = g.keys[a];
    const SE3 T_W_A_guess = a == 0 ? SE3() : SE3::exp((Vec6() << 0.8, -0.5, 0.1, 0, 0, 8 * kDeg).finished());
    std::vector<std::pair<KeyframeKey, SE3>> T_A_K;
    SE3 T = g.truth.at(keys[0]);
    std::vector<SE3> meas;
    for (std::size_t i = 0; i < keys.size(); ++i) {
      if (i > 0) {
        const SE3 rel = g.truth.at(keys[i - 1]).inverse() * g.truth.at(keys[i]);
        const SE3 z = rel * bias * SE3::exp(randomTangent(rng, st, sr));
        meas.push_back(z);
        T = T * z;
      }
      T_A_K.emplace_back(keys[i], T);
    }
    EXPECT_TRUE(pg.addAgentNodes(T_A_K, T_W_A_guess).ok());
    for (std::size_t i = 1; i < keys.size(); ++i) {
      EXPECT_TRUE(pg.addOdometryEdge(keys[i - 1], keys[i], meas[i - 1], diagInformation(st, sr)).ok());
    }
  }
  for (const LoopSpec& l : loops) {
    EXPECT_TRUE(pg.addLoopEdge(l.a, l.b, l.T_a_b, diagInformation(0.02, 0.3 * kDeg)).ok());
  }
  EXPECT_TRUE(pg.fixFirstPoseOf(0).ok());
  *initial = pg.poses();
  return pg;
}

std::vector<LoopSpec> trueLoops(const Graph& g, std::mt19937& rng) {
  std::vector<LoopSpec> loops;
  // Inter-agent: pairs of keyframes closer than 1.5 m; intra: agent 0 revisits its start.
  for (std::uint32_t a = 0; a < 2; ++a) {
    for (std::size_t i = 0; i < g.keys[a].size(); i += 3) {
      for (std::uint32_t b = a; b < 2; ++b) {
        for (std::size_t j = 0; j < g.keys[b].size(); j += 3) {
          if (a == b && j < i + 40) continue;
          const SE3& Ta = g.truth.at(g.keys[a][i]);
          const SE3& Tb = g.truth.at(g.keys[b][j]);
          if ((Ta.translation() - Tb.translation()).norm() > 1.5) continue;
          loops.push_back({g.keys[a][i], g.keys[b][j],
                           Ta.inverse() * Tb * SE3::exp(randomTangent(rng, 0.02, 0.3 * kDeg))});
        }
      }
    }
  }
  return loops;
}

TEST(PoseGraph, TwoAgentDriftIsCorrected) {
  std::mt19937 rng(7);
  const Graph g = makeTruth(120);
  const auto loops = trueLoops(g, rng);
  ASSERT_GE(loops.size(), 8u);
  std::map<KeyframeKey, SE3> initial;
  PoseGraph pg = buildGraph(g, PoseGraphParams(), loops, rng, &initial);
  auto res = pg.optimize();
  ASSERT_TRUE(res.ok()) << res.error();
  const double before = ate(initial, g.truth), after = ate(pg.poses(), g.truth);
  std::printf("%zu nodes, %zu loops: ATE before %.3f m after %.3f m, %d iterations, %.1f ms\n",
              pg.numNodes(), loops.size(), before, after, res->iterations, res->time_ms);
  EXPECT_GT(before, 1.0);
  EXPECT_LT(after, 0.25);
  EXPECT_LT(after, 0.15 * before);
}

TEST(PoseGraph, RobustLossSurvivesOneGrossOutlierLoop) {
  const Graph g = makeTruth(120);
  double ate_clean = 0, ate_robust = 0, ate_plain = 0;
  for (int variant = 0; variant < 3; ++variant) {
    std::mt19937 rng(7);  // same noise in every variant
    auto loops = trueLoops(g, rng);
    if (variant > 0) {  // wrong by 4 m and 60 degrees, confidently
      const KeyframeKey a = g.keys[0][10], b = g.keys[1][70];
      loops.push_back({a, b, SE3(expSO3(Vec3(0, 0, 60 * kDeg)), Vec3(4, 1, 0))});
    }
    PoseGraphParams params;
    params.loop_loss = variant == 2 ? "none" : "cauchy";
    if (variant == 2) params.odometry_reweight_rounds = 0;  // no robust mechanism at all
    std::map<KeyframeKey, SE3> initial;
    PoseGraph pg = buildGraph(g, params, loops, rng, &initial);
    auto res = pg.optimize();
    ASSERT_TRUE(res.ok()) << res.error();
    const double e = ate(pg.poses(), g.truth);
    (variant == 0 ? ate_clean : variant == 1 ? ate_robust : ate_plain) = e;
  }
  std::printf("ATE clean %.3f m, outlier+cauchy %.3f m, outlier without loss %.3f m\n", ate_clean,
              ate_robust, ate_plain);
  EXPECT_LT(ate_robust, ate_clean + 0.03);
  EXPECT_GT(ate_plain, 3 * ate_robust);  // the outlier really would hurt
}

TEST(PoseGraph, RejectsBadInput) {
  PoseGraph pg;
  const KeyframeKey a{0, 0, 1}, b{0, 0, 2}, c{1, 0, 1};
  EXPECT_TRUE(pg.addNode(a, SE3()).ok());
  EXPECT_TRUE(pg.addNode(b, SE3()).ok());
  EXPECT_FALSE(pg.addNode(a, SE3()).ok());
  EXPECT_FALSE(pg.addOdometryEdge(a, c, SE3(), Mat6::Identity()).ok());
  const Status s = pg.addLoopEdge(a, b, SE3(), -Mat6::Identity());
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.error().find("positive definite"), std::string::npos);
  EXPECT_FALSE(pg.optimize().ok());  // no edges
  EXPECT_TRUE(pg.addLoopEdge(a, b, SE3(), Mat6::Identity()).ok());
  EXPECT_EQ(pg.numLoopEdges(), 1u);
  pg.clearLoopEdges();
  EXPECT_EQ(pg.numLoopEdges(), 0u);
  PoseGraphParams p;
  p.loop_loss = "tukeyish";
  EXPECT_FALSE(p.validate().ok());
  PoseGraphParams q;
  q.odometry_reweight_window = -1;
  const Status window = q.validate();
  ASSERT_FALSE(window.ok());
  EXPECT_NE(window.error().find("odometry_reweight_window"), std::string::npos);
}

}  // namespace
}  // namespace server
}  // namespace hermes
