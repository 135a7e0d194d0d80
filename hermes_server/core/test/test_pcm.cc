// PCM: chi-square quantiles, maximum clique, consistent-loop selection.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <functional>
#include <random>

#include "hermes/server/pcm.h"

namespace hermes {
namespace server {
namespace {

constexpr double kDeg = M_PI / 180.0;

TEST(Pcm, ChiSquareQuantiles) {
  EXPECT_NEAR(chi2Quantile(0.95, 6), 12.5916, 1e-3);
  EXPECT_NEAR(chi2Quantile(0.99, 6), 16.8119, 1e-3);
  EXPECT_NEAR(chi2Quantile(0.95, 1), 3.8415, 1e-3);
  EXPECT_NEAR(chi2Quantile(0.5, 2), 1.3863, 1e-3);
  EXPECT_NEAR(chi2Quantile(0.999, 6), 22.4577, 1e-3);
}

int bruteForceCliqueSize(const std::vector<std::vector<char>>& adj) {
  const int n = static_cast<int>(adj.size());
  int best = 0;
  for (std::uint32_t mask = 1; mask < (1u << n); ++mask) {
    const int size = __builtin_popcount(mask);
    if (size <= best) continue;
    bool ok = true;
    for (int i = 0; i < n && ok; ++i) {
      if (!(mask >> i & 1)) continue;
      for (int j = i + 1; j < n && ok; ++j) ok = !(mask >> j & 1) || adj[i][j];
    }
    if (ok) best = size;
  }
  return best;
}

bool isClique(const std::vector<std::vector<char>>& adj, const std::vector<int>& c) {
  for (std::size_t i = 0; i < c.size(); ++i) {
    for (std::size_t j = i + 1; j < c.size(); ++j) {
      if (!adj[c[i]][c[j]]) return false;
    }
  }
  return true;
}

std::vector<std::vector<char>> randomGraph(int n, double p, std::mt19937& rng) {
  std::bernoulli_distribution e(p);
  std::vector<std::vector<char>> adj(n, std::vector<char>(n, 0));
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j < n; ++j) adj[i][j] = adj[j][i] = e(rng);
  }
  return adj;
}

TEST(Pcm, ExactCliqueMatchesBruteForce) {
  std::mt19937 rng(1);
  for (int trial = 0; trial < 30; ++trial) {
    const auto adj = randomGraph(14, 0.2 + 0.02 * trial, rng);
    bool exact = false;
    const auto c = maximumClique(adj, 40, &exact);
    EXPECT_TRUE(exact);
    EXPECT_TRUE(isClique(adj, c));
    EXPECT_EQ(static_cast<int>(c.size()), bruteForceCliqueSize(adj)) << "trial " << trial;
  }
}

/// The greedy heuristic counted pair by pair (maximumClique's reference).
std::vector<int> plainGreedyClique(const std::vector<std::vector<char>>& adj) {
  const int n = static_cast<int>(adj.size());
  std::vector<int> best;
  for (int start = 0; start < n; ++start) {
    std::vector<int> clique{start}, cand;
    for (int j = 0; j < n; ++j)
      if (j != start && adj[start][j]) cand.push_back(j);
    while (!cand.empty()) {
      int best_k = 0, best_deg = -1;
      for (std::size_t k = 0; k < cand.size(); ++k) {
        int d = 0;
        for (int c : cand) d += (c != cand[k] && adj[cand[k]][c]);
        if (d > best_deg) best_deg = d, best_k = static_cast<int>(k);
      }
      const int v = cand[best_k];
      clique.push_back(v);
      std::vector<int> next;
      for (int c : cand)
        if (c != v && adj[v][c]) next.push_back(c);
      cand.swap(next);
    }
    if (clique.size() > best.size()) best = clique;
  }
  std::sort(best.begin(), best.end());
  return best;
}

TEST(Pcm, GreedyCliqueOnBitsetsMakesThePlainChoices) {
  std::mt19937 rng(5);
  for (int n : {1, 2, 63, 64, 65, 129, 200}) {
    for (double p : {0.05, 0.3, 0.8}) {
      const auto adj = randomGraph(n, p, rng);
      bool exact = true;
      EXPECT_EQ(maximumClique(adj, 0, &exact), plainGreedyClique(adj)) << "n " << n << " p " << p;
      EXPECT_FALSE(exact);
    }
  }
}

TEST(Pcm, LargeGraphsExactAndGreedyFindPlantedClique) {
  std::mt19937 rng(2);
  for (int n : {40, 120}) {
    auto adj = randomGraph(n, 0.3, rng);
    // Plant a clique of 25 vertices.
    std::vector<int> planted(n);
    for (int i = 0; i < n; ++i) planted[i] = i;
    std::shuffle(planted.begin(), planted.end(), rng);
    planted.resize(25);
    for (int a : planted) {
      for (int b : planted) {
        if (a != b) adj[a][b] = 1;
      }
    }
    bool exact = false;
    const auto t0 = std::chrono::steady_clock::now();
    const auto c = maximumClique(adj, 40, &exact);
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    EXPECT_EQ(exact, n <= 40);
    EXPECT_TRUE(isClique(adj, c));
    EXPECT_GE(c.size(), 25u) << "n " << n;
    std::printf("n=%d %s clique %zu in %.2f ms\n", n, exact ? "exact" : "greedy", c.size(), ms);
  }
}

Vec6 noise(std::mt19937& rng, double st, double sr) {
  std::normal_distribution<double> n(0, 1);
  Vec6 xi;
  xi << st * n(rng), st * n(rng), st * n(rng), sr * n(rng), sr * n(rng), sr * n(rng);
  return xi;
}

Mat6 diagCov(double st, double sr) {
  Vec6 d;
  d << Vec3::Constant(st * st), Vec3::Constant(sr * sr);
  return d.asDiagonal();
}

/// Two agents' odometry (noisy, so their frames drift from the truth) and loops
/// measured from the truth: true loops agree with the odometry up to drift.
struct World {
  std::map<KeyframeKey, SE3> truth;
  std::vector<KeyframeKey> keys[2];
  OdometryChain chain;
};

void makeWorld(World* w, std::mt19937& rng, int n) {
  const double st = 0.01, sr = 0.2 * kDeg;
  for (std::uint32_t a = 0; a < 2; ++a) {
    SE3 T_A_K;
    for (int i = 0; i < n; ++i) {
      const double th = 2 * M_PI * i / n + a;
      const KeyframeKey key{a, 1, static_cast<KeyframeId>(100 + 2 * i)};
      w->truth[key] = SE3(expSO3(Vec3(0, 0, th + M_PI / 2)),
                          Vec3(5 * std::cos(th) + 2.0 * a, 5 * std::sin(th), 0.2 * std::sin(2 * th)));
      if (i > 0) {
        const SE3 rel = w->truth.at(w->keys[a].back()).inverse() * w->truth.at(key);
        T_A_K = T_A_K * rel * SE3::exp(noise(rng, st, sr));
      } else {
        T_A_K = w->truth.at(key);
      }
      ASSERT_TRUE(w->chain.addKeyframe(key, T_A_K).ok());
      if (i > 0) {
        ASSERT_TRUE(w->chain.addEdge(w->keys[a].back(), key, diagCov(st, sr).inverse()).ok());
      }
      w->keys[a].push_back(key);
    }
  }
}

TEST(Pcm, KeepsConsistentLoopsAndDropsFalseOnes) {
  int false_accepted = 0, true_kept = 0, true_total = 0;
  for (int seed = 1; seed <= 5; ++seed) {
    std::mt19937 rng(seed);
    World w;
    makeWorld(&w, rng, 80);
    std::vector<LoopCandidate> loops;
    std::uniform_int_distribution<int> pick(0, 79);
    const Mat6 loop_cov = diagCov(0.03, 0.5 * kDeg);
    for (int k = 0; k < 10; ++k) {  // true inter-agent loops
      const KeyframeKey a = w.keys[0][pick(rng)], b = w.keys[1][pick(rng)];
      LoopCandidate l;
      l.id = k;
      // Alternate orientation to exercise the reversal.
      l.a = k % 2 ? a : b;
      l.b = k % 2 ? b : a;
      l.T_a_b = w.truth.at(l.a).inverse() * w.truth.at(l.b) * SE3::exp(noise(rng, 0.03, 0.5 * kDeg));
      l.covariance = loop_cov;
      loops.push_back(l);
    }
    for (int k = 0; k < 5; ++k) {  // false loops: the right place, wrong pose
      LoopCandidate l;
      l.id = 100 + k;
      l.a = w.keys[0][pick(rng)];
      l.b = w.keys[1][pick(rng)];
      std::uniform_real_distribution<double> u(-1, 1);
      l.T_a_b = SE3(expSO3(Vec3(u(rng), u(rng), u(rng)) * 60 * kDeg), Vec3(u(rng), u(rng), u(rng)) * 4);
      l.covariance = loop_cov;
      loops.push_back(l);
    }
    const PcmResult r = selectConsistentLoops(loops, w.chain.query(), PcmParams());
    EXPECT_EQ(r.groups, 1);
    EXPECT_TRUE(r.all_exact);
    EXPECT_EQ(r.odometry_failures, 0);
    EXPECT_EQ(r.accepted.size() + r.rejected.size(), loops.size());
    for (auto id : r.accepted) {
      if (id >= 100) ++false_accepted; else ++true_kept;
    }
    true_total += 10;
    std::printf("seed %d: accepted %zu rejected %zu in %.2f ms\n", seed, r.accepted.size(),
                r.rejected.size(), r.time_ms);
  }
  EXPECT_EQ(false_accepted, 0);
  EXPECT_GE(true_kept, 0.9 * true_total);
}

TEST(Pcm, IntraAgentLoopsAndMissingOdometry) {
  std::mt19937 rng(4);
  World w;
  makeWorld(&w, rng, 60);
  std::vector<LoopCandidate> loops;
  for (int k = 0; k < 6; ++k) {
    LoopCandidate l;
    l.id = k;
    l.a = w.keys[0][5 + k];
    l.b = w.keys[0][50 + k];
    l.T_a_b = w.truth.at(l.a).inverse() * w.truth.at(l.b) * SE3::exp(noise(rng, 0.02, 0.3 * kDeg));
    l.covariance = diagCov(0.02, 0.3 * kDeg);
    loops.push_back(l);
  }
  LoopCandidate bad = loops[0];
  bad.id = 99;
  bad.T_a_b = bad.T_a_b * SE3(expSO3(Vec3(0, 0, 0.5)), Vec3(1.5, 0, 0));
  loops.push_back(bad);
  PcmResult r = selectConsistentLoops(loops, w.chain.query(), PcmParams());
  EXPECT_EQ(r.accepted.size(), 6u);
  ASSERT_EQ(r.rejected.size(), 1u);
  EXPECT_EQ(r.rejected[0], 99u);

  // A loop to an unknown trajectory has no odometry: it cannot be verified.
  OdometryChain empty;
  r = selectConsistentLoops(loops, empty.query(), PcmParams{0.99, 40, 2});
  EXPECT_TRUE(r.accepted.empty());
  EXPECT_GT(r.odometry_failures, 0);
}

TEST(Pcm, OdometryChainComposesCovariance) {
  OdometryChain chain;
  const KeyframeKey k0{0, 0, 1}, k1{0, 0, 2}, k2{0, 0, 3};
  ASSERT_TRUE(chain.addKeyframe(k0, SE3()).ok());
  ASSERT_TRUE(chain.addKeyframe(k1, SE3(expSO3(Vec3(0, 0, 0.3)), Vec3(1, 0, 0))).ok());
  ASSERT_TRUE(chain.addKeyframe(k2, SE3(expSO3(Vec3(0, 0, 0.6)), Vec3(2, 0.3, 0))).ok());
  const Mat6 c = diagCov(0.1, 0.01);
  ASSERT_TRUE(chain.addEdge(k0, k1, c.inverse()).ok());
  EXPECT_FALSE(chain.addEdge(k0, k2, c.inverse()).ok());  // not consecutive
  EXPECT_FALSE(chain.relative(k0, k2).ok());              // edge k1->k2 missing
  ASSERT_TRUE(chain.addEdge(k1, k2, c.inverse()).ok());
  auto r = chain.relative(k0, k2);
  ASSERT_TRUE(r.ok());
  // Monte Carlo check of the propagated covariance of T_k0_k2.
  std::mt19937 rng(9);
  const SE3 E0 = SE3().inverse() * SE3(expSO3(Vec3(0, 0, 0.3)), Vec3(1, 0, 0));
  const SE3 E1 = SE3(expSO3(Vec3(0, 0, 0.3)), Vec3(1, 0, 0)).inverse() *
                 SE3(expSO3(Vec3(0, 0, 0.6)), Vec3(2, 0.3, 0));
  Mat6 mc = Mat6::Zero();
  const int N = 20000;
  for (int i = 0; i < N; ++i) {
    const SE3 T = E0 * SE3::exp(noise(rng, 0.1, 0.01)) * E1 * SE3::exp(noise(rng, 0.1, 0.01));
    const Vec6 xi = (r->T.inverse() * T).log();
    mc += xi * xi.transpose() / N;
  }
  EXPECT_LT((mc - r->covariance).norm(), 0.05 * r->covariance.norm());
  auto back = chain.relative(k2, k0);
  ASSERT_TRUE(back.ok());
  EXPECT_LT((back->T * r->T).log().norm(), 1e-12);
}

/// Loops between agent 0 (sound odometry) and agent 1, whose odometry the
/// caller corrupts without it knowing: `corrupt(i, rel)` is applied to the
/// measured edge into keyframe i (rel: its true relative pose). Right loops
/// every `loop_every` keyframes.
struct CorruptedWorld {
  World w;
  std::vector<LoopCandidate> loops;
};

CorruptedWorld makeCorruptedWorld(std::mt19937& rng, int n, int loop_every,
                                  const std::function<SE3(int, const SE3&)>& corrupt) {
  CorruptedWorld j;
  World& w = j.w;
  const double st = 0.005, sr = 0.1 * kDeg;
  for (std::uint32_t a = 0; a < 2; ++a) {
    SE3 T_A_K;
    for (int i = 0; i < n; ++i) {
      const double th = 2 * M_PI * i / n;
      const KeyframeKey key{a, 1, static_cast<KeyframeId>(i)};
      w.truth[key] = SE3(expSO3(Vec3(0, 0, th + M_PI / 2)), Vec3((5 + 0.3 * a) * std::cos(th), 5 * std::sin(th), 0));
      if (i > 0) {
        const SE3 rel = w.truth.at(w.keys[a].back()).inverse() * w.truth.at(key);
        T_A_K = T_A_K * rel * SE3::exp(noise(rng, st, sr)) * (a == 1 ? corrupt(i, rel) : SE3());
        EXPECT_TRUE(w.chain.addKeyframe(key, T_A_K).ok());
        EXPECT_TRUE(w.chain.addEdge(w.keys[a].back(), key, diagCov(st, sr).inverse()).ok());
      } else {
        T_A_K = w.truth.at(key);
        EXPECT_TRUE(w.chain.addKeyframe(key, T_A_K).ok());
      }
      w.keys[a].push_back(key);
    }
  }
  for (int i = 1; i < n; i += loop_every) {  // right loops all along
    LoopCandidate l;
    l.id = j.loops.size();
    l.a = w.keys[0][i];
    l.b = w.keys[1][i - 1];
    l.T_a_b = w.truth.at(l.a).inverse() * w.truth.at(l.b) * SE3::exp(noise(rng, 0.01, 0.2 * kDeg));
    l.covariance = diagCov(0.01, 0.2 * kDeg);
    j.loops.push_back(l);
  }
  return j;
}

/// Agent 1's odometry jumps by 0.5 m / 10 deg between keyframes `jump` and jump+1.
CorruptedWorld makeJumpWorld(std::mt19937& rng, int n, int jump) {
  const SE3 kick(expSO3(Vec3(0, 0, 10 * kDeg)), Vec3(0.5, 0, 0));
  return makeCorruptedWorld(rng, n, 3, [&](int i, const SE3&) { return i == jump + 1 ? kick : SE3(); });
}

/// Agent 1's odometry drifts silently by `fraction` of the distance (sideways,
/// as a scale error would not) over keyframes [from, to).
CorruptedWorld makeDriftWorld(std::mt19937& rng, int n, int loop_every, int from, int to, double fraction) {
  return makeCorruptedWorld(rng, n, loop_every, [=](int i, const SE3& rel) {
    if (i < from || i >= to) return SE3();
    return SE3(Quat::Identity(), Vec3(0, fraction * rel.translation().norm(), 0));
  });
}

TEST(Pcm, LoopsOnBothSidesOfAnOdometryJumpAreSegments) {
  std::mt19937 rng(9);
  CorruptedWorld j = makeJumpWorld(rng, 60, 35);
  PcmParams p;
  p.min_clique_size = 3;
  const PcmResult classic = [&] {
    PcmParams c = p;
    c.max_segments = 1;
    return selectConsistentLoops(j.loops, j.w.chain.query(), c);
  }();
  // Classic PCM keeps one side of the jump only.
  EXPECT_LT(classic.accepted.size(), j.loops.size() - 5);
  const PcmResult r = selectConsistentLoops(j.loops, j.w.chain.query(), p);
  EXPECT_GE(r.segment_cliques, 1);
  EXPECT_GE(r.accepted.size(), j.loops.size() - 1) << "accepted " << r.accepted.size() << " of " << j.loops.size();
}

TEST(Pcm, ASecondCliqueAmongTheFirstIsNotASegment) {
  // Wrong loops that agree with each other but interleave with the right ones:
  // no odometry break explains them, so they stay rejected.
  std::mt19937 rng(10);
  CorruptedWorld j = makeJumpWorld(rng, 60, 1000);  // no jump
  const std::size_t right = j.loops.size();
  const SE3 wrong_offset(expSO3(Vec3(0, 0, 25 * kDeg)), Vec3(1.5, -0.8, 0.2));
  for (int i = 10; i < 50; i += 8) {
    LoopCandidate l;
    l.id = j.loops.size();
    l.a = j.w.keys[0][i];
    l.b = j.w.keys[1][i + 1];
    l.T_a_b = j.w.truth.at(l.a).inverse() * wrong_offset * j.w.truth.at(l.b);
    l.covariance = diagCov(0.01, 0.2 * kDeg);
    j.loops.push_back(l);
  }
  PcmParams p;
  p.min_clique_size = 3;
  const PcmResult r = selectConsistentLoops(j.loops, j.w.chain.query(), p);
  EXPECT_EQ(r.segment_cliques, 0);
  for (auto id : r.accepted) EXPECT_LT(id, right) << "a wrong loop was accepted";
  EXPECT_GE(r.accepted.size(), right - 1);
}

TEST(Pcm, RightLoopsUnderASilentDriftStayConsistent) {
  // 3 % of the distance over half the circle (~0.5 m), a loop every second
  // keyframe: without the drift allowance the random-walk model splits them.
  std::mt19937 rng(11);
  CorruptedWorld j = makeDriftWorld(rng, 80, 2, 20, 60, 0.03);
  PcmParams p;
  p.min_clique_size = 3;
  PcmParams none = p;
  none.drift_fraction = 0;
  none.drift_rad_per_m = 0;
  const PcmResult before = selectConsistentLoops(j.loops, j.w.chain.query(), none);
  const PcmResult after = selectConsistentLoops(j.loops, j.w.chain.query(), p);
  std::printf("drift: %zu loops, accepted without allowance %zu, with %zu\n", j.loops.size(),
              before.accepted.size(), after.accepted.size());
  EXPECT_LT(before.accepted.size(), j.loops.size() - 5) << "the drift should defeat the random-walk model";
  EXPECT_GE(after.accepted.size(), j.loops.size() - 1);
}

TEST(Pcm, TheDriftAllowanceStillRejectsWrongLoops) {
  // The same drifting world with wrong loops among the right ones: a wrong
  // place 0.5-1.5 m / 10-30 deg off, alone or agreeing with other wrong ones.
  std::mt19937 rng(12);
  CorruptedWorld j = makeDriftWorld(rng, 80, 2, 20, 60, 0.03);
  const std::size_t right = j.loops.size();
  std::uniform_real_distribution<double> u(-1, 1);
  for (int i = 5; i < 75; i += 6) {
    LoopCandidate l;
    l.id = j.loops.size();
    l.a = j.w.keys[0][i];
    l.b = j.w.keys[1][i + 1];
    const Vec3 dir = Vec3(u(rng), u(rng), 0.2 * u(rng)).normalized();
    const double metres = 0.5 + 0.5 * (1 + u(rng)), deg = 10 + 10 * (1 + u(rng));
    const SE3 off(expSO3(Vec3(0, 0, (u(rng) > 0 ? 1 : -1) * deg * kDeg)), metres * dir);
    l.T_a_b = j.w.truth.at(l.a).inverse() * off * j.w.truth.at(l.b);
    l.covariance = diagCov(0.01, 0.2 * kDeg);
    j.loops.push_back(l);
  }
  PcmParams p;
  p.min_clique_size = 3;
  const PcmResult r = selectConsistentLoops(j.loops, j.w.chain.query(), p);
  for (auto id : r.accepted) EXPECT_LT(id, right) << "a wrong loop was accepted";
  EXPECT_GE(r.accepted.size(), right - 1);
}

TEST(Pcm, TheCacheGivesTheSameVerdictsAndComputesOnlyNewPairs) {
  // Loops arrive in batches (as submaps do), right and wrong ones, across a
  // jump: every cached run selects exactly what an uncached run selects, and
  // computes only the pairs with a new loop.
  std::mt19937 rng(13);
  CorruptedWorld j = makeJumpWorld(rng, 60, 35);
  const SE3 wrong_offset(expSO3(Vec3(0, 0, 20 * kDeg)), Vec3(1.0, -0.5, 0.1));
  for (int i = 3; i < 57; i += 9) {
    LoopCandidate l;
    l.id = 1000 + i;
    l.a = j.w.keys[0][i];
    l.b = j.w.keys[1][i + 2];
    l.T_a_b = j.w.truth.at(l.a).inverse() * wrong_offset * j.w.truth.at(l.b);
    l.covariance = diagCov(0.01, 0.2 * kDeg);
    j.loops.push_back(l);
  }
  std::shuffle(j.loops.begin(), j.loops.end(), rng);
  PcmParams p;
  p.min_clique_size = 3;
  PcmCache cache;
  std::vector<LoopCandidate> seen;
  for (std::size_t k = 0; k < j.loops.size(); ++k) {
    seen.push_back(j.loops[k]);
    if (seen.size() % 4 != 0 && k + 1 != j.loops.size()) continue;
    const long before = static_cast<long>(seen.size()) - (seen.size() % 4 ? seen.size() % 4 : 4);
    const PcmResult plain = selectConsistentLoops(seen, j.w.chain.query(), p);
    const PcmResult cached = selectConsistentLoops(seen, j.w.chain.query(), p, &cache);
    EXPECT_EQ(cached.accepted, plain.accepted) << "after " << seen.size() << " loops";
    EXPECT_EQ(cached.rejected, plain.rejected);
    const long n = static_cast<long>(seen.size());
    EXPECT_EQ(cached.pairs_computed + cached.pairs_cached, n * (n - 1) / 2);
    EXPECT_EQ(cached.pairs_computed, n * (n - 1) / 2 - before * (before - 1) / 2);
  }
  // A re-measured loop (here: made wrong) is computed again once forgotten.
  LoopCandidate& moved = seen.front();
  moved.T_a_b = moved.T_a_b * SE3(expSO3(Vec3(0, 0.4, 0)), Vec3(0, 1.2, 0));
  const long n = static_cast<long>(seen.size());
  cache.forget(moved.id);
  const PcmResult plain = selectConsistentLoops(seen, j.w.chain.query(), p);
  const PcmResult cached = selectConsistentLoops(seen, j.w.chain.query(), p, &cache);
  EXPECT_EQ(cached.pairs_computed, n - 1);
  EXPECT_EQ(cached.accepted, plain.accepted);
  EXPECT_TRUE(std::count(cached.rejected.begin(), cached.rejected.end(), moved.id));
  EXPECT_GT(cache.bytes(), 0u);
  cache.clear();
  EXPECT_EQ(selectConsistentLoops(seen, j.w.chain.query(), p, &cache).pairs_cached, 0);
}

TEST(Pcm, TheChainRevisionGrowsOnlyWhenAKeyframeIsInsertedBetweenOthers) {
  OdometryChain chain;
  ASSERT_TRUE(chain.addKeyframe({0, 0, 2}, SE3()).ok());
  ASSERT_TRUE(chain.addKeyframe({0, 0, 4}, SE3()).ok());
  ASSERT_TRUE(chain.addKeyframe({1, 0, 1}, SE3()).ok());  // another trajectory
  EXPECT_EQ(chain.revision(), 0u);
  ASSERT_TRUE(chain.addKeyframe({0, 0, 3}, SE3()).ok());
  EXPECT_EQ(chain.revision(), 1u);
}

TEST(Pcm, DriftAllowanceGrowsWithThePath) {
  PcmParams p;
  p.drift_fraction = 0.02;
  p.drift_rad_per_m = 0.001;
  EXPECT_EQ(driftAllowance(0, p), Mat6::Zero());
  const Mat6 a = driftAllowance(10, p);
  EXPECT_NEAR(a(0, 0), 0.2 * 0.2, 1e-12);
  EXPECT_NEAR(a(5, 5), 0.01 * 0.01, 1e-12);
  EXPECT_NEAR(a(0, 1), 0, 1e-15);
  // The chain reports its path length in both directions.
  OdometryChain chain;
  const KeyframeKey k0{0, 0, 1}, k1{0, 0, 2}, k2{0, 0, 3};
  ASSERT_TRUE(chain.addKeyframe(k0, SE3()).ok());
  ASSERT_TRUE(chain.addKeyframe(k1, SE3(Quat::Identity(), Vec3(3, 0, 0))).ok());
  ASSERT_TRUE(chain.addKeyframe(k2, SE3(Quat::Identity(), Vec3(3, 4, 0))).ok());
  ASSERT_TRUE(chain.addEdge(k0, k1, diagCov(0.1, 0.01).inverse()).ok());
  ASSERT_TRUE(chain.addEdge(k1, k2, diagCov(0.1, 0.01).inverse()).ok());
  EXPECT_NEAR(chain.relative(k0, k2)->path_length_m, 7.0, 1e-9);
  EXPECT_NEAR(chain.relative(k2, k0)->path_length_m, 7.0, 1e-9);
}

}  // namespace
}  // namespace server
}  // namespace hermes
