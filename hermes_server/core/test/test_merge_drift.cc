// The merge must repair a robot whose odometry drifts or jumps: a synthetic
// three-robot graph where robots 0 (the world) and 2 know their path and robot 1 drifts
// (a yaw bias and a scale error on every step, as a fast robot's visual
// odometry does) or jumps once (a relocalisation error it did not notice),
// with exact loops between them. Odometry information comes from the one
// odometry noise model, loop information as the loop closer reports it, the
// pose graph and PCM run with their defaults: the drifting robot's merged
// error must end well below its odometry error, and the robots that know their
// path must not be dragged along. With the per-edge prior the agents used
// before (3 mm / 1 mrad per edge, whatever the distance) and no odometry
// re-weighting (the graph as it was), the loops lose against the odometry and
// the drift stays; without the re-weighting the drift is split among all
// robots (the common frame bends).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <random>

#include "hermes/core/odometry_noise.h"
#include "hermes/server/pcm.h"
#include "hermes/server/pose_graph.h"

namespace hermes {
namespace server {
namespace {

constexpr int kKeyframes = 120;
constexpr int kLoopEvery = 4;

/// Ground truth: a 6-m-radius circle at 0.3 m per keyframe, camera looking ahead.
SE3 truePose(int k, double lateral) {
  const double r = 6.0, step = 0.3 / r, a = k * step;
  const Vec3 p((r + lateral) * std::cos(a), (r + lateral) * std::sin(a), 0.0);
  const Mat3 R = Eigen::AngleAxisd(a + M_PI / 2, Vec3::UnitZ()).toRotationMatrix();
  return SE3(R, p);
}

struct Robot {
  std::vector<SE3> truth, odometry;  // T_W_K and the robot's own estimate (T_A_K)
};

enum class Fault { kNone, kDrift, kJump };

Robot makeRobot(double lateral, Fault fault, double drift, std::mt19937& rng) {
  std::normal_distribution<double> n(0, 1);
  Robot r;
  for (int k = 0; k < kKeyframes; ++k) r.truth.push_back(truePose(k, lateral));
  r.odometry.push_back(r.truth.front());
  for (int k = 1; k < kKeyframes; ++k) {
    SE3 step = r.truth[k - 1].inverse() * r.truth[k];
    Vec6 noise;
    noise << 0.001 * n(rng), 0.001 * n(rng), 0.001 * n(rng), 0.0003 * n(rng), 0.0003 * n(rng),
        0.0003 * n(rng);
    step = step * SE3::exp(noise);
    if (fault == Fault::kDrift) {  // drift 1: 1.5 mrad yaw bias (0.3 deg/m) and 1.5 % scale error per step
      step = SE3(step.quat() * Quat(Eigen::AngleAxisd(0.0015 * drift, Vec3::UnitZ())),
                 step.translation() * (1 + 0.015 * drift));
    }
    if (fault == Fault::kJump && k == kKeyframes / 2) {  // 0.5 m / 10 deg, unnoticed
      step = step * SE3(Quat(Eigen::AngleAxisd(10 * M_PI / 180, Vec3::UnitZ())), Vec3(0.5, 0, 0));
    }
    r.odometry.push_back(r.odometry.back() * step);
  }
  return r;
}

double rmse(const std::vector<SE3>& est, const std::vector<SE3>& truth) {
  double s = 0;
  for (std::size_t i = 0; i < est.size(); ++i)
    s += (est[i].translation() - truth[i].translation()).squaredNorm();
  return std::sqrt(s / est.size());
}

Mat6 stiffPrior() {  // what every odometry edge carried before the noise model
  Vec6 d;
  d << Vec3::Constant(1 / (0.003 * 0.003)), Vec3::Constant(1 / (0.001 * 0.001));
  return d.asDiagonal();
}

Mat6 loopCovariance() {  // a typical 17-point loop after the covariance inflation
  Vec6 d;
  d << Vec3::Constant(0.01 * 0.01), Vec3::Constant(0.003 * 0.003);
  return d.asDiagonal();
}

struct Outcome {
  double odometry_rmse = 0, merged_rmse = 0;              // the faulty robot
  double sound_odometry_rmse = 0, sound_merged_rmse = 0;  // robot 0
  int loops_accepted = 0, loops_total = 0;
  double loop_weight_faulty = 0, loop_weight_sound = 0;  // mean weight of loops with / without robot 1
};

/// Robots 0 (the world) and 2 know their path, robot 1 has `fault`; loops every
/// kLoopEvery keyframes between each pair, judged by PCM through the odometry,
/// the accepted ones in the graph. Returns robot 1's errors (and robot 0's).
PcmParams testPcm() {
  PcmParams pcm;
  pcm.min_clique_size = 3;
  return pcm;
}

Outcome mergeRobots(Fault fault, bool noise_model, const PoseGraphParams& graph_params,
                    double drift = 1.0, const PcmParams& pcm = testPcm()) {
  std::mt19937 rng(11);
  const std::vector<Robot> robots = {makeRobot(0.0, Fault::kNone, 0, rng), makeRobot(0.4, fault, drift, rng),
                                     makeRobot(-0.4, Fault::kNone, 0, rng)};
  const std::uint32_t n_robots = static_cast<std::uint32_t>(robots.size());
  const OdometryNoiseParams noise;
  auto info = [&](const SE3& step) {
    return noise_model ? odometryInformation(step, -1, false, noise) : stiffPrior();
  };
  auto key = [](std::uint32_t robot, int k) { return KeyframeKey{robot, 1, KeyframeId(k)}; };
  OdometryChain chain;
  PoseGraph g(graph_params);
  for (std::uint32_t a = 0; a < n_robots; ++a)
    for (int k = 0; k < kKeyframes; ++k) {
      EXPECT_TRUE(chain.addKeyframe(key(a, k), robots[a].odometry[k]).ok());
      EXPECT_TRUE(g.addNode(key(a, k), robots[a].odometry[k]).ok());
      if (k == 0) continue;
      const SE3 step = robots[a].odometry[k - 1].inverse() * robots[a].odometry[k];
      EXPECT_TRUE(chain.addEdge(key(a, k - 1), key(a, k), info(step)).ok());
      EXPECT_TRUE(g.addOdometryEdge(key(a, k - 1), key(a, k), step, info(step)).ok());
    }
  std::vector<LoopCandidate> loops;
  std::normal_distribution<double> n(0, 1);
  const std::pair<std::uint32_t, std::uint32_t> pairs[] = {{0, 1}, {0, 2}, {1, 2}};
  for (int p = 0; p < 3; ++p) {
    const auto [ra, rb] = pairs[p];
    for (int k = 2 + p; k < kKeyframes; k += kLoopEvery) {
      LoopCandidate c;
      c.id = loops.size();
      c.a = key(ra, k);
      c.b = key(rb, k - 1);
      Vec6 e;
      e << 0.003 * n(rng), 0.003 * n(rng), 0.003 * n(rng), 0.001 * n(rng), 0.001 * n(rng), 0.001 * n(rng);
      c.T_a_b = robots[ra].truth[k].inverse() * robots[rb].truth[k - 1] * SE3::exp(e);
      c.covariance = loopCovariance();
      loops.push_back(c);
    }
  }
  const PcmResult accepted = selectConsistentLoops(loops, chain.query(), pcm);
  const Mat6 loop_info = *invertSpd(loopCovariance());
  for (std::uint64_t id : accepted.accepted)
    EXPECT_TRUE(g.addLoopEdge(loops[id].a, loops[id].b, loops[id].T_a_b, loop_info).ok());
  EXPECT_TRUE(g.fixFirstPoseOf(0).ok());
  auto res = g.optimize();
  EXPECT_TRUE(res.ok()) << (res.ok() ? "" : res.error());
  if (res.ok()) {
    EXPECT_TRUE(res->converged) << res->termination << ": " << res->report;
  }
  if (std::getenv("HERMES_DEBUG_GRAPH")) {
    for (const EdgeResidual& e : g.residuals())
      if (e.loop || e.chi2 > 4)
        std::printf("%s %u:%lu-%u:%lu res %.3f m %.3f deg chi2 %.1f w %.2f\n", e.loop ? "loop" : "odo",
                    e.a.agent, (unsigned long)e.a.id, e.b.agent, (unsigned long)e.b.id, e.error_m,
                    e.error_rad * 57.3, e.chi2, e.weight);
    if (res.ok()) std::printf("%s, %d re-weighting rounds\n", res->report.c_str(), res->reweight_rounds);
  }
  auto merged = [&](std::uint32_t robot) {
    std::vector<SE3> m;
    for (int k = 0; k < kKeyframes; ++k) m.push_back(*g.pose(key(robot, k)));
    return m;
  };
  Outcome o;
  o.odometry_rmse = rmse(robots[1].odometry, robots[1].truth);
  o.merged_rmse = rmse(merged(1), robots[1].truth);
  o.sound_odometry_rmse = rmse(robots[0].odometry, robots[0].truth);
  o.sound_merged_rmse = rmse(merged(0), robots[0].truth);
  double w_faulty = 0, w_sound = 0;
  int n_faulty = 0, n_sound = 0;
  for (const EdgeResidual& e : g.residuals()) {
    if (!e.loop) continue;
    const bool faulty = e.a.agent == 1 || e.b.agent == 1;
    (faulty ? w_faulty : w_sound) += e.weight;
    ++(faulty ? n_faulty : n_sound);
  }
  o.loop_weight_faulty = n_faulty ? w_faulty / n_faulty : 0;
  o.loop_weight_sound = n_sound ? w_sound / n_sound : 0;
  o.loops_accepted = static_cast<int>(accepted.accepted.size());
  o.loops_total = static_cast<int>(loops.size());
  std::printf("robot 1: odometry %.3f m, merged %.3f m; robot 0: odometry %.3f m, merged %.3f m; loops %d/%d\n",
              o.odometry_rmse, o.merged_rmse, o.sound_odometry_rmse, o.sound_merged_rmse,
              o.loops_accepted, o.loops_total);
  return o;
}

TEST(MergeDrift, LoopsRepairADriftingRobot) {
  // Drift far beyond the noise model (2 sigma of bias on every step): PCM keeps
  // most loops (in segments), the graph bends the drifting robot onto them.
  const Outcome o = mergeRobots(Fault::kDrift, true, PoseGraphParams());
  EXPECT_GT(o.odometry_rmse, 0.5) << "the fixture should drift by decimetres";
  EXPECT_GE(o.loops_accepted, 0.7 * o.loops_total);
  EXPECT_LT(o.merged_rmse, 0.15 * o.odometry_rmse);
  // The sound robots are not dragged along.
  EXPECT_LT(o.sound_merged_rmse, o.sound_odometry_rmse + 0.01);
}

TEST(MergeDrift, ADriftWithinTheNoiseModelIsRepairedToo) {
  // A third of the bias (within the model on each step, 14 sigma over the
  // path): every loop passes PCM; least squares alone would split the drift
  // among all robots tied by loops (the common frame bends), the re-weighting
  // puts it back on the robot whose odometry disagrees with everyone else.
  const Outcome o = mergeRobots(Fault::kDrift, true, PoseGraphParams(), 1.0 / 3);
  EXPECT_GT(o.odometry_rmse, 0.15);
  EXPECT_GE(o.loops_accepted, o.loops_total - 2);
  EXPECT_LT(o.merged_rmse, 0.2 * o.odometry_rmse);
  EXPECT_LT(o.sound_merged_rmse, o.sound_odometry_rmse + 0.01);
  PoseGraphParams plain;
  plain.odometry_reweight_rounds = 0;
  const Outcome split = mergeRobots(Fault::kDrift, true, plain, 1.0 / 3);
  EXPECT_GT(split.sound_merged_rmse, split.sound_odometry_rmse + 0.03);
}

TEST(MergeDrift, LoopsOnADriftingRobotsRigsAreTrustedLess) {
  // A loop's rigs are placed by its robots' odometry: where that odometry is
  // re-weighted, the loop is trusted less too (loop_rig_edges); loops between
  // the sound robots keep their weight.
  const Outcome with = mergeRobots(Fault::kDrift, true, PoseGraphParams(), 1.0 / 3);
  PoseGraphParams off;
  off.loop_rig_edges = 0;
  const Outcome without = mergeRobots(Fault::kDrift, true, off, 1.0 / 3);
  std::printf("loop weights with robot 1: %.3f (off: %.3f); between the others: %.3f (off: %.3f)\n",
              with.loop_weight_faulty, without.loop_weight_faulty, with.loop_weight_sound,
              without.loop_weight_sound);
  EXPECT_LT(with.loop_weight_faulty, 0.5 * without.loop_weight_faulty);
  EXPECT_GT(with.loop_weight_sound, 0.8 * without.loop_weight_sound);
  EXPECT_LT(with.merged_rmse, 0.2 * with.odometry_rmse);
  EXPECT_LT(with.sound_merged_rmse, with.sound_odometry_rmse + 0.01);
}

TEST(MergeDrift, TheStiffPerEdgePriorKeepsTheDrift) {
  // The failure this guards against: odometry claimed mm-accurate whatever the
  // distance outweighs the loops, which PCM and the robust loss then give up.
  PoseGraphParams before;  // the graph as it was: no re-weighting
  before.odometry_reweight_rounds = 0;
  before.loop_rig_edges = 0;
  PcmParams pcm_before = testPcm();  // and PCM without its drift allowance
  pcm_before.drift_fraction = 0;
  pcm_before.drift_rad_per_m = 0;
  const Outcome o = mergeRobots(Fault::kDrift, false, before, 1.0, pcm_before);
  EXPECT_GT(o.merged_rmse, 0.3 * o.odometry_rmse);
  EXPECT_LT(o.loops_accepted, o.loops_total);  // PCM gives right loops up, too
}

TEST(MergeDrift, LoopsRepairAnUnnoticedOdometryJump) {
  PoseGraphParams p;
  p.odometry_loss = "cauchy";
  const Outcome o = mergeRobots(Fault::kJump, true, p);
  EXPECT_GT(o.odometry_rmse, 0.3);
  // Loops on both sides of the jump survive PCM (two segments) ...
  EXPECT_GE(o.loops_accepted, o.loops_total - 2);
  // ... and the jump edge gives way to them.
  EXPECT_LT(o.merged_rmse, 0.1 * o.odometry_rmse);
  EXPECT_LT(o.sound_merged_rmse, o.sound_odometry_rmse + 0.01);
}

TEST(MergeDrift, SoundOdometryStaysSound) {
  const Outcome o = mergeRobots(Fault::kNone, true, PoseGraphParams());
  EXPECT_EQ(o.loops_accepted, o.loops_total);
  EXPECT_LE(o.merged_rmse, o.odometry_rmse + 0.005);
  EXPECT_LE(o.sound_merged_rmse, o.sound_odometry_rmse + 0.005);
}

}  // namespace
}  // namespace server
}  // namespace hermes
