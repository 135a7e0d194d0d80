// Incremental pose-graph solves (PoseGraph::holdBeyond): only the nodes near
// what changed are free; the result must match a full solve of the same graph
// (three robots on a circle, odometry 3 mm / 0.1 deg per keyframe, loops 1 cm).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>

#include "hermes/server/pose_graph.h"

namespace hermes {
namespace server {
namespace {

constexpr double kDeg = M_PI / 180.0;

Mat6 information(double sigma_t, double sigma_r) {
  Vec6 d;
  d << Vec3::Constant(1 / (sigma_t * sigma_t)), Vec3::Constant(1 / (sigma_r * sigma_r));
  return d.asDiagonal();
}

SE3 noisy(const SE3& T, std::mt19937& rng, double st, double sr) {
  std::normal_distribution<double> n(0, 1);
  Vec6 xi;
  xi << st * n(rng), st * n(rng), st * n(rng), sr * n(rng), sr * n(rng), sr * n(rng);
  return T * SE3::exp(xi);
}

/// Robot r's keyframe i on a circle of radius 3 m (phase offset per robot,
/// height per robot), looking along its path.
SE3 truth(std::uint32_t r, std::size_t i) {
  const double a = 0.05 * static_cast<double>(i) + 0.7 * r;
  return SE3(expSO3(Vec3(0, 0, a + M_PI / 2)), Vec3(3 * std::cos(a), 3 * std::sin(a), 0.3 * r));
}

struct Measurements {
  std::map<std::pair<KeyframeKey, KeyframeKey>, SE3> odometry, loops;
};

/// Three robots with `n[r]` keyframes: noisy odometry, loops between keyframes
/// of different robots less than 0.5 m apart (every third keyframe).
void measure(const std::vector<std::size_t>& n, std::mt19937& rng, Measurements* m) {
  auto key = [](std::uint32_t r, std::size_t i) { return KeyframeKey{r, 0, static_cast<KeyframeId>(i)}; };
  for (std::uint32_t r = 0; r < n.size(); ++r)
    for (std::size_t i = 1; i < n[r]; ++i)
      if (!m->odometry.count({key(r, i - 1), key(r, i)}))
        m->odometry[{key(r, i - 1), key(r, i)}] = noisy(truth(r, i - 1).inverse() * truth(r, i), rng, 0.003, 0.1 * kDeg);
  for (std::uint32_t a = 0; a < n.size(); ++a)
    for (std::uint32_t b = a + 1; b < n.size(); ++b)
      for (std::size_t i = 0; i < n[a]; i += 3)
        for (std::size_t j = 0; j < n[b]; j += 3)
          if ((truth(a, i).translation() - truth(b, j).translation()).norm() < 0.5 &&
              !m->loops.count({key(a, i), key(b, j)}))
            m->loops[{key(a, i), key(b, j)}] = noisy(truth(a, i).inverse() * truth(b, j), rng, 0.01, 0.2 * kDeg);
}

/// The graph of `m` with initial poses: `start` where given, otherwise chained
/// from the previous keyframe by odometry.
PoseGraph build(const Measurements& m, const std::map<KeyframeKey, SE3>& start,
                const PoseGraphParams& params = PoseGraphParams()) {
  PoseGraph g(params);
  std::map<KeyframeKey, SE3> init = start;
  for (const auto& [ab, T] : m.odometry) {  // keys in order per robot
    if (!init.count(ab.first)) init[ab.first] = truth(ab.first.agent, ab.first.id);
    if (!init.count(ab.second)) init[ab.second] = init.at(ab.first) * T;
  }
  for (const auto& [k, T] : init) EXPECT_TRUE(g.addNode(k, T).ok());
  for (const auto& [ab, T] : m.odometry) EXPECT_TRUE(g.addOdometryEdge(ab.first, ab.second, T, information(0.003, 0.1 * kDeg)).ok());
  for (const auto& [ab, T] : m.loops) EXPECT_TRUE(g.addLoopEdge(ab.first, ab.second, T, information(0.01, 0.2 * kDeg)).ok());
  EXPECT_TRUE(g.setFixed(KeyframeKey{0, 0, 0}).ok());
  return g;
}

TEST(PoseGraphIncremental, HoldsWhatIsFartherThanHopsFromTheSeeds) {
  PoseGraph g;
  for (KeyframeId i = 0; i < 10; ++i) ASSERT_TRUE(g.addNode({0, 0, i}, SE3(Mat3::Identity(), Vec3(i, 0, 0))).ok());
  for (KeyframeId i = 1; i < 10; ++i)
    ASSERT_TRUE(g.addOdometryEdge({0, 0, i - 1}, {0, 0, i}, SE3(Mat3::Identity(), Vec3(1, 0, 0)), information(0.1, 0.1)).ok());
  ASSERT_TRUE(g.setFixed({0, 0, 0}).ok());
  EXPECT_EQ(g.holdBeyond({{0, 0, 9}}, 3), 4u);              // 6, 7, 8, 9
  EXPECT_EQ(g.holdBeyond({{0, 0, 5}, {7, 7, 7}}, 1), 3u);  // 4, 5, 6; an unknown seed is ignored
  EXPECT_EQ(g.holdBeyond({}, 5), 0u);
  EXPECT_EQ(g.holdBeyond({{0, 0, 2}}, 100), 9u);            // all but the fixed one
  // A cap on the free nodes: the nearest first; every seed stays free.
  EXPECT_EQ(g.holdBeyond({{0, 0, 9}}, 3, 2), 2u);            // 9, then 8
  EXPECT_EQ(g.holdBeyond({{0, 0, 5}}, 100, 3), 3u);          // 5, then 4 and 6
  EXPECT_EQ(g.holdBeyond({{0, 0, 1}, {0, 0, 5}, {0, 0, 9}}, 2, 2), 3u);
}

/// A full and an incremental solve of the same grown graph under `params`;
/// `tight`: the incremental one must match the full one closely.
void compareIncrementalWithFull(const PoseGraphParams& params, bool tight, std::size_t max_free = 0) {
  std::mt19937 rng(3);
  // Before: three robots of 60 keyframes, solved in full.
  Measurements m;
  measure({60, 60, 60}, rng, &m);
  PoseGraph before = build(m, {}, params);
  ASSERT_TRUE(before.optimize().ok());
  const std::map<KeyframeKey, SE3> solved = before.poses();
  // A new submap: robot 0 flies 10 keyframes on, closing loops with the others.
  const std::size_t loops_before = m.loops.size();
  measure({70, 60, 60}, rng, &m);
  ASSERT_GT(m.loops.size(), loops_before);
  std::vector<KeyframeKey> touched;
  for (KeyframeId i = 60; i < 70; ++i) touched.push_back({0, 0, i});
  PoseGraph full = build(m, solved, params);
  PoseGraph incremental = build(m, solved, params);
  const std::map<KeyframeKey, SE3> unsolved = incremental.poses();  // new keyframes chained by odometry
  ASSERT_TRUE(full.optimize().ok());
  const std::size_t free = incremental.holdBeyond(touched, 8, max_free);
  auto r = incremental.optimize();
  ASSERT_TRUE(r.ok()) << r.error();
  double worst_t = 0, worst_new = 0, worst_r = 0, ate_full = 0, ate_incr = 0, moved = 0, rms_incr = 0, rms_none = 0;
  for (const auto& [k, T] : full.poses()) {
    const SE3 Ti = *incremental.pose(k);
    rms_incr += (T.translation() - Ti.translation()).squaredNorm();
    if (!solved.count(k)) worst_new = std::max(worst_new, (T.translation() - Ti.translation()).norm());
    rms_none += (T.translation() - unsolved.at(k).translation()).squaredNorm();
    if (solved.count(k)) moved = std::max(moved, (T.translation() - solved.at(k).translation()).norm());
    worst_t = std::max(worst_t, (T.translation() - Ti.translation()).norm());
    worst_r = std::max(worst_r, rotationAngle((T.inverse() * Ti).rotation()));
    ate_full += (T.translation() - truth(k.agent, k.id).translation()).squaredNorm();
    ate_incr += (Ti.translation() - truth(k.agent, k.id).translation()).squaredNorm();
  }
  const double n = static_cast<double>(full.numNodes());
  rms_incr = std::sqrt(rms_incr / n);
  rms_none = std::sqrt(rms_none / n);
  std::printf("%zu of %zu nodes free; the full solve moved old nodes up to %.2f mm; vs the full solve: "
              "incremental rms %.2f mm, max %.2f mm (new keyframes %.2f mm), %.3f deg; not solved rms %.2f mm; ATE full %.2f mm, "
              "incremental %.2f mm\n",
              free, full.numNodes(), moved * 1e3, rms_incr * 1e3, worst_t * 1e3, worst_new * 1e3, worst_r / kDeg,
              rms_none * 1e3, std::sqrt(ate_full / n) * 1e3, std::sqrt(ate_incr / n) * 1e3);
  EXPECT_LT(free, full.numNodes() / 2);  // touches far fewer nodes
  if (max_free > 0) {
    EXPECT_LE(free, max_free);
  }
  EXPECT_GT(free, touched.size());       // and more than the new ones
  EXPECT_LT(std::sqrt(ate_incr / n), 1.2 * std::sqrt(ate_full / n) + 0.002);  // as accurate
  if (!tight) {
    EXPECT_LT(worst_t, 0.03);
    EXPECT_LT(rms_incr, rms_none);  // closer to the full solve than not solving at all
    return;
  }
  // Held nodes keep the last solution: a dangling end far from the change
  // that the full solve swings a few mm lags until the next full solve.
  EXPECT_LT(worst_t, 0.01);              // within 1 cm of the full solve everywhere
  EXPECT_LT(worst_r, 0.2 * kDeg);
  EXPECT_LT(worst_new, 0.003);           // where the change is, within 3 mm
  EXPECT_LT(rms_incr, 0.003);
  EXPECT_LT(rms_incr, 0.7 * rms_none);   // closer than not solving at all
}

TEST(PoseGraphIncremental, MatchesTheFullSolveAndMovesFewerNodes) {
  // Odometry re-weighted per robot and per +-5-edge stretch (scope both): the
  // robot level of a sound robot stays at the median, so both solves weigh
  // every edge alike and agree within millimetres.
  PoseGraphParams both;
  both.odometry_reweight_scope = "both";
  compareIncrementalWithFull(both, true);
}

TEST(PoseGraphIncremental, WithLocalReweightingIsAsAccurateAsTheFullSolve) {
  // The default scope (local): each edge's scale follows the chi2 of its
  // +-5-edge stretch, which noise alone moves by tens of percent; the held
  // part's stale residuals enter the incremental solve's median, so its scales,
  // hence its poses, drift from the full solve's by a few mm (measured: rms
  // 4.5 mm, max 18 mm against 4.8 mm not solving at all), while its accuracy
  // is the full solve's (ATE 43.9 vs 44.9 mm). The next full solve
  // (full_every) realigns them.
  compareIncrementalWithFull(PoseGraphParams(), false);
}

TEST(PoseGraphIncremental, ACappedFreeSetStaysCloseToTheFullSolve) {
  // pose_graph.incremental_max_free: where loops tie every robot, 8 hops reach
  // the whole graph; the cap frees the nodes nearest the change only (here 40
  // of the 78 that 8 hops free).
  PoseGraphParams both;
  both.odometry_reweight_scope = "both";
  compareIncrementalWithFull(both, false, 40);
}

}  // namespace
}  // namespace server
}  // namespace hermes
