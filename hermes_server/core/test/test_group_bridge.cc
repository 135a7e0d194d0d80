// PCM across tie groups: loops spread 1-2 per pair between groups of tied
// trajectories are accepted together when consistent through the ties.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>

#include "hermes/server/group_bridge.h"

namespace hermes {
namespace server {
namespace {

constexpr double kDeg = M_PI / 180.0;

Mat6 diagCov(double st, double sr) {
  Vec6 d;
  d << Vec3::Constant(st * st), Vec3::Constant(sr * sr);
  return d.asDiagonal();
}

Vec6 noise(std::mt19937& rng, double st, double sr) {
  std::normal_distribution<double> n(0, 1);
  Vec6 xi;
  xi << st * n(rng), st * n(rng), st * n(rng), sr * n(rng), sr * n(rng), sr * n(rng);
  return xi;
}

/// Three robots flying overlapping circles in one room (agents 0, 1, 2), each
/// with its own odometry frame A (offset from the world) and noisy odometry;
/// loops are measured from the truth with noise.
struct Swarm {
  static constexpr int kRobots = 3, kKeyframes = 60;
  std::map<KeyframeKey, SE3> truth;     ///< T_W_C
  std::vector<KeyframeKey> keys[kRobots];
  SE3 T_W_A[kRobots];
  std::map<KeyframeKey, SE3> odometry;  ///< T_A_C as the robot estimates it
  OdometryChain chain;
  std::mt19937 rng{7};
  double st = 0.005, sr = 0.1 * kDeg;
  std::uint64_t next_id = 0;

  explicit Swarm(double odometry_noise_scale = 1.0) {
    st *= odometry_noise_scale;
    sr *= odometry_noise_scale;
    for (std::uint32_t a = 0; a < kRobots; ++a) {
      T_W_A[a] = SE3(expSO3(Vec3(0.1 * a, -0.2 * a, 0.7 * a)), Vec3(3.0 * a, -1.0 * a, 0.5 * a));
      SE3 T_A_C;
      for (int i = 0; i < kKeyframes; ++i) {
        const double th = 2 * M_PI * i / kKeyframes + 0.8 * a;
        const KeyframeKey key{a, 1, static_cast<KeyframeId>(10 + i)};
        truth[key] = SE3(expSO3(Vec3(0, 0, th + M_PI / 2)),
                         Vec3(4 * std::cos(th) + 0.5 * a, 4 * std::sin(th), 0.3 * std::sin(2 * th)));
        if (i == 0) {
          T_A_C = T_W_A[a].inverse() * truth[key];
        } else {
          const SE3 rel = truth.at(keys[a].back()).inverse() * truth.at(key);
          T_A_C = T_A_C * rel * SE3::exp(noise(rng, st, sr));
        }
        odometry[key] = T_A_C;
        EXPECT_TRUE(chain.addKeyframe(key, T_A_C).ok());
        const Mat6 information = diagCov(std::max(st, 1e-6), std::max(sr, 1e-6)).inverse();
        if (i > 0) EXPECT_TRUE(chain.addEdge(keys[a].back(), key, information).ok());
        keys[a].push_back(key);
      }
    }
  }

  LoopCandidate rightLoop(std::uint32_t a, int i, std::uint32_t b, int j) {
    LoopCandidate l;
    l.id = next_id++;
    l.a = keys[a][i];
    l.b = keys[b][j];
    l.T_a_b = truth.at(l.a).inverse() * truth.at(l.b) * SE3::exp(noise(rng, 0.01, 0.3 * kDeg));
    l.covariance = diagCov(0.02, 0.5 * kDeg);
    return l;
  }
  /// A loop at a place that looks the same: a wrong pose by `off_m` / `off_deg`.
  LoopCandidate wrongLoop(std::uint32_t a, int i, std::uint32_t b, int j, double off_m, double off_deg) {
    LoopCandidate l = rightLoop(a, i, b, j);
    l.T_a_b = l.T_a_b * SE3(expSO3(Vec3(0, 0, off_deg * kDeg)), Vec3(off_m, -0.5 * off_m, 0));
    return l;
  }
};

std::set<std::uint64_t> ids(const std::vector<LoopCandidate>& loops) {
  std::set<std::uint64_t> s;
  for (const LoopCandidate& l : loops) s.insert(l.id);
  return s;
}

TEST(GroupBridge, TheRelativePoseThroughTiesMatchesTheTruth) {
  Swarm w(0.0);  // exact odometry, exact loops: the composition must be exact
  TieGroups g(w.chain.query());
  LoopCandidate t01 = w.rightLoop(0, 5, 1, 40), t12 = w.rightLoop(1, 20, 2, 33);
  t01.T_a_b = w.truth.at(t01.a).inverse() * w.truth.at(t01.b);
  t12.T_a_b = w.truth.at(t12.a).inverse() * w.truth.at(t12.b);
  g.tie(t01);
  g.tie(reversedLoop(t12));  // either orientation
  EXPECT_EQ(g.group({0, 1}), g.group({2, 1}));
  const KeyframeKey from = w.keys[0][50], to = w.keys[2][3];
  const Expected<RelativePose> r = g.relative(from, to);
  ASSERT_TRUE(r.ok()) << r.error();
  const SE3 truth = w.truth.at(from).inverse() * w.truth.at(to);
  EXPECT_LT((r->T.inverse() * truth).log().norm(), 1e-9);
  EXPECT_GT(r->path_length_m, 0.0);
  Eigen::LDLT<Mat6> ldlt(r->covariance);
  EXPECT_TRUE(ldlt.isPositive());  // odometry 0, the two ties' covariances carried through
  const Expected<RelativePose> back = g.relative(to, from);
  ASSERT_TRUE(back.ok());
  EXPECT_LT((back->T * r->T).log().norm(), 1e-9);

  TieGroups apart(w.chain.query());
  apart.tie(t01);
  EXPECT_FALSE(apart.relative(from, to).ok());  // robot 2 is tied to nobody
  EXPECT_NE(apart.group({2, 1}), apart.group({0, 1}));
}

/// Robots 1 and 2 tied by 4 loops (accepted); robot 0 meets each briefly: 2
/// right loops with each, plus one wrong loop. Per pair none reaches 3.
TEST(GroupBridge, BriefMeetingsWithSeveralRobotsAreAcceptedTogether) {
  Swarm w;
  std::vector<LoopCandidate> loops;
  for (auto [i, j] : {std::pair{2, 30}, {12, 40}, {25, 50}, {40, 8}}) loops.push_back(w.rightLoop(1, i, 2, j));
  const std::set<std::uint64_t> ties = ids(loops);
  const std::vector<LoopCandidate> right = {w.rightLoop(0, 10, 1, 28), w.rightLoop(1, 35, 0, 14),
                                            w.rightLoop(0, 44, 2, 5), w.rightLoop(0, 48, 2, 9)};
  const LoopCandidate wrong = w.wrongLoop(0, 30, 2, 21, 0.6, 12);
  loops.insert(loops.end(), right.begin(), right.end());
  loops.push_back(wrong);

  // Per-pair PCM: the 1-2 tie is kept, every loop of robot 0 rejected (fewer than 3 per pair).
  PcmParams params;
  params.min_clique_size = 3;
  const PcmResult per_pair = selectConsistentLoops(loops, w.chain.query(), params);
  EXPECT_EQ(std::set<std::uint64_t>(per_pair.accepted.begin(), per_pair.accepted.end()), ties);

  const BridgeResult b = bridgeTieGroups(loops, ties, w.chain.query(), params);
  EXPECT_EQ(b.bridges, 1);
  EXPECT_EQ(std::set<std::uint64_t>(b.accepted.begin(), b.accepted.end()), ids(right));
  EXPECT_EQ(b.odometry_failures, 0);

  params.bridge_min_loops = 0;  // off
  EXPECT_TRUE(bridgeTieGroups(loops, ties, w.chain.query(), params).accepted.empty());
  params.bridge_min_loops = 5;  // more than the four right ones
  EXPECT_TRUE(bridgeTieGroups(loops, ties, w.chain.query(), params).accepted.empty());
}

TEST(GroupBridge, WrongLoopsBetweenGroupsStayRejected) {
  int accepted_wrong = 0;
  for (int seed = 1; seed <= 5; ++seed) {
    Swarm w;
    w.rng.seed(seed);
    std::vector<LoopCandidate> loops;
    for (auto [i, j] : {std::pair{2, 30}, {12, 40}, {25, 50}}) loops.push_back(w.rightLoop(1, i, 2, j));
    const std::set<std::uint64_t> ties = ids(loops);
    // Aliased places: each wrong by its own offset, 1-2 per pair.
    loops.push_back(w.wrongLoop(0, 10, 1, 28, 0.5, 5));
    loops.push_back(w.wrongLoop(0, 20, 1, 8, -0.7, -15));
    loops.push_back(w.wrongLoop(0, 44, 2, 5, 0.9, 30));
    loops.push_back(w.wrongLoop(2, 15, 0, 52, 0.3, -8));
    const BridgeResult b = bridgeTieGroups(loops, ties, w.chain.query(), PcmParams());
    accepted_wrong += static_cast<int>(b.accepted.size());
  }
  EXPECT_EQ(accepted_wrong, 0);
}

TEST(GroupBridge, ConsistentLoopsOfOnePairAloneAreNotABridge) {
  Swarm w;
  std::vector<LoopCandidate> loops = {w.rightLoop(0, 10, 1, 28), w.rightLoop(0, 20, 1, 38),
                                      w.rightLoop(0, 30, 1, 48)};
  // Per-pair PCM decides a single pair (here: nothing tied, so it would accept them itself).
  EXPECT_TRUE(bridgeTieGroups(loops, {}, w.chain.query(), PcmParams()).accepted.empty());
}

/// Robot 0 anchored; robots 1 and 2 tied to each other and bridged to robot 0 by
/// two loops each: neither has the three of its own that anchoring needs, the
/// group has four, carried to each through the tie.
TEST(GroupBridge, AnUnanchoredTrajectoryIsPlacedThroughItsGroup) {
  Swarm w;
  GlobalMap map;
  for (std::uint32_t a = 0; a < Swarm::kRobots; ++a) {
    TrajectoryMap& t = map.trajectories[{a, 1}];
    t.agent = a;
    t.session = 1;
    t.anchored = a == 0;
    for (const KeyframeKey& k : w.keys[a]) {
      StoredKeyframe& kf = t.keyframes[k.id];
      kf.keyframe.id = k.id;
      kf.keyframe.T_A_C = w.odometry.at(k);
      if (t.anchored) kf.T_W_C = w.truth.at(k);  // as a solved pose graph would hold it
    }
  }
  auto edge = [](const LoopCandidate& l) {
    LoopEdge e;
    e.id = l.id;
    e.a = l.a;
    e.b = l.b;
    e.T_a_b = l.T_a_b;
    e.covariance = l.covariance;
    e.accepted = true;
    return e;
  };
  TieGroups groups(w.chain.query());
  for (const LoopCandidate& l : {w.rightLoop(1, 2, 2, 30), w.rightLoop(1, 12, 2, 40), w.rightLoop(1, 25, 2, 50),
                                 w.rightLoop(0, 10, 1, 28), w.rightLoop(1, 35, 0, 14),
                                 w.rightLoop(0, 44, 2, 5), w.rightLoop(0, 48, 2, 9)}) {
    map.loops.push_back(edge(l));
    groups.tie(l);
    EXPECT_EQ(loopCandidate(map.loops.back()).id, l.id);
  }
  for (std::uint32_t a : {1u, 2u}) {
    const std::vector<SE3> estimates = groupAnchorEstimates(map, groups, map.trajectories.at({a, 1}));
    EXPECT_EQ(estimates.size(), 2u);  // the other member's two loops to robot 0
    for (const SE3& T_W_A : estimates) {
      // Odometry drift along up to 100 keyframes of chain (0.1 deg each on a 4-m
      // circle) and the ties' noise: decimetres at most, a start for the pose graph.
      EXPECT_LT((T_W_A.translation() - w.T_W_A[a].translation()).norm(), 0.3) << "robot " << a;
      EXPECT_LT(rotationAngle((T_W_A.inverse() * w.T_W_A[a]).rotation()), 5 * kDeg) << "robot " << a;
    }
  }
  EXPECT_TRUE(groupAnchorEstimates(map, groups, map.trajectories.at({0, 1})).empty());
}

}  // namespace
}  // namespace server
}  // namespace hermes
