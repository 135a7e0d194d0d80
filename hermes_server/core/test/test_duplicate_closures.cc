// Near-duplicate closures (server.map.duplicate_neighbours): within one merge,
// a closure whose query and candidate keyframes each sit next to those of an
// earlier closure that gave a loop (same two trajectories) is not verified;
// one whose earlier twin gave no loop still is; with duplicate_min_pair_loops
// only where the merge's first round tied the two trajectories that often.
#include <gtest/gtest.h>

#include <cstdlib>
#include <iostream>
#include <iterator>
#include <map>

#include "hermes/server/server.h"
#include "support/multi_agent_fixture.h"

namespace hermes {
namespace server {
namespace {

struct Seen {
  KeyframeKey query, candidate;
  int qpos = -1, cpos = -1;  ///< positions in their trajectories when tried
  LoopStatus status = LoopStatus::kBadInput;
  std::size_t merge = 0;     ///< which merge it belonged to
};

struct Trace {
  std::vector<Seen> attempts;  ///< with a candidate
  int verified = 0, skipped = 0;
  std::size_t accepted = 0;
  int merged = 0;
};

int position(const GlobalMap& map, const KeyframeKey& k) {
  const TrajectoryMap* t = map.trajectory(k.agent, k.session);
  if (!t) return -1;
  auto it = t->keyframes.find(k.id);
  return it == t->keyframes.end() ? -1 : static_cast<int>(std::distance(t->keyframes.begin(), it));
}

Trace run(const fixture::Fixture& fx, int duplicate_neighbours, int min_pair_loops = 0, int budget = 0,
          int swarm_budget = 0) {
  ServerParams params;
  params.map.duplicate_neighbours = duplicate_neighbours;
  params.map.duplicate_min_pair_loops = min_pair_loops;
  params.map.closure_budget = budget;
  params.map.closure_budget_swarm = swarm_budget;
  params.map.closure_budget_min_robots = 1;  // the fixture's two robots share it
  auto created = Server::create(params, HERMES_SOURCE_DIR);
  EXPECT_TRUE(created.ok()) << created.error();
  Server& server = **created;
  Trace trace;
  std::size_t merge = 0;
  server.mapManager().setAttemptHook([&](const LoopAttempt& a) {
    if (!a.candidate) return;
    Seen s{a.query, a.candidate->key, position(server.map(), a.query),
           position(server.map(), a.candidate->key), a.status, merge};
    trace.attempts.push_back(s);
    const bool skipped = a.status == LoopStatus::kSkippedDuplicate || a.status == LoopStatus::kSkippedBudget;
    (skipped ? trace.skipped : trace.verified) += 1;
  });
  double now = 0;
  for (std::size_t r = 0; r < fx.agents[0].frames.size() || r < fx.agents[1].frames.size(); ++r) {
    for (const auto& agent : fx.agents) {
      if (r >= agent.frames.size()) continue;
      EXPECT_EQ(server.onFrame(agent.frames[r].data(), agent.frames[r].size(), nullptr, now += 1).verdict,
                ArrivalVerdict::kAccept);
      ++merge;  // one submap per process() call at most: merges are told apart by frame
      server.process(now, 1);  // the merge alone (a submap waited: nothing deferred runs)
      ++merge;
      server.process(now, -1);  // nothing waits: deferred closures (closure_budget)
    }
  }
  // The closures a budget deferred, verified while no submap waits.
  for (int idle = 0; idle < 1000 && server.deferredClosures() > 0; ++idle) {
    ++merge;
    server.process(now += 1, -1);
  }
  EXPECT_EQ(server.deferredClosures(), 0u);
  EXPECT_EQ(server.counters().merge_errors, 0u) << server.counters().last_error;
  trace.accepted = server.mapManager().loopsAccepted();
  trace.merged = server.mapManager().agentsMerged();
  return trace;
}

bool sameTrajectory(const KeyframeKey& a, const KeyframeKey& b) {
  return a.agent == b.agent && a.session == b.session;
}

class DuplicateClosures : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    auto fx = fixture::hallPair(15.0, 200);
    ASSERT_TRUE(fx.ok()) << fx.error();
    fx_ = new fixture::Fixture(*fx);
    off_ = new Trace(run(*fx, 0));
    on_ = new Trace(run(*fx, 2));
    sparse_ = new Trace(run(*fx, 2, 1000));
    budget_ = new Trace(run(*fx, 2, 6, kBudget));
    swarm_ = new Trace(run(*fx, 2, 6, 0, 2 * kBudget));
  }
  static void TearDownTestSuite() {
    delete fx_;
    delete off_;
    delete on_;
    delete sparse_;
    delete budget_;
    delete swarm_;
  }
  static constexpr int kBudget = 4;
  static fixture::Fixture* fx_;
  static Trace* off_;
  static Trace* on_;
  static Trace* sparse_;  ///< duplicate_min_pair_loops above any merge's loops
  static Trace* budget_;  ///< closure_budget kBudget
  static Trace* swarm_;   ///< closure_budget_swarm 2 x kBudget: kBudget each once both robots merge
};
fixture::Fixture* DuplicateClosures::fx_ = nullptr;
Trace* DuplicateClosures::off_ = nullptr;
Trace* DuplicateClosures::on_ = nullptr;
Trace* DuplicateClosures::sparse_ = nullptr;
Trace* DuplicateClosures::budget_ = nullptr;
Trace* DuplicateClosures::swarm_ = nullptr;

TEST_F(DuplicateClosures, FewerClosuresVerifiedSameRobotsMerged) {
  ASSERT_TRUE(off_ && on_);
  EXPECT_EQ(off_->skipped, 0);
  EXPECT_GT(on_->skipped, 0);  // adjacent query keyframes do propose the same places
  EXPECT_LT(on_->verified, off_->verified);
  EXPECT_EQ(off_->merged, 2);
  EXPECT_EQ(on_->merged, 2);
  EXPECT_GE(on_->accepted, 3u);
  std::cout << "[ info ] verified " << off_->verified << " -> " << on_->verified << " (skipped "
            << on_->skipped << "), loops accepted " << off_->accepted << " -> " << on_->accepted
            << "\n";
}

TEST_F(DuplicateClosures, OnlyNeighboursOfALoopOfTheSameMergeAreSkipped) {
  ASSERT_TRUE(on_);
  const auto& at = on_->attempts;
  for (std::size_t i = 0; i < at.size(); ++i) {
    if (at[i].status != LoopStatus::kSkippedDuplicate) continue;
    bool twin = false;
    for (std::size_t j = 0; j < i && !twin; ++j)
      twin = at[j].merge == at[i].merge && at[j].status == LoopStatus::kAccepted &&
             sameTrajectory(at[j].query, at[i].query) &&
             sameTrajectory(at[j].candidate, at[i].candidate) &&
             std::abs(at[j].qpos - at[i].qpos) <= 2 && std::abs(at[j].cpos - at[i].cpos) <= 2;
    EXPECT_TRUE(twin) << "skipped attempt " << i << " has no earlier loop next to it";
  }
}

TEST_F(DuplicateClosures, PairsWithFewLoopsInTheMergeKeepEveryClosure) {
  ASSERT_TRUE(off_ && sparse_);
  EXPECT_EQ(sparse_->skipped, 0);
  EXPECT_EQ(sparse_->verified, off_->verified);
  EXPECT_EQ(sparse_->accepted, off_->accepted);
}

// server.map.closure_budget: no merge verifies more closures than the budget;
// the rest are deferred and verified, a budget per call, while no submap
// waits: in the end every closure was verified and the same loops found.
TEST_F(DuplicateClosures, TheBudgetCapsEveryMergeAndDefersTheRest) {
  ASSERT_TRUE(on_ && budget_);
  std::map<KeyframeKey, std::size_t> first_seen;  // a query's first attempt is in its own merge
  std::map<std::size_t, int> own, deferred;       // verified per process() call
  int over_budget = 0;
  for (const Seen& s : budget_->attempts) {
    first_seen.emplace(s.query, s.merge);
    if (s.status == LoopStatus::kSkippedBudget) ++over_budget;
    else if (s.status != LoopStatus::kSkippedDuplicate)
      ++(first_seen[s.query] == s.merge ? own : deferred)[s.merge];
  }
  for (const auto& [merge, n] : own) EXPECT_LE(n, kBudget) << "merge " << merge;
  for (const auto& [merge, n] : deferred) EXPECT_LE(n, kBudget) << "deferred, call " << merge;
  EXPECT_GT(over_budget, 0) << "the fixture's merges should propose more than " << kBudget;
  EXPECT_FALSE(deferred.empty());
  EXPECT_EQ(budget_->merged, 2);
  // Every deferred closure was verified later (none dropped: fewer than
  // deferred_closures waited), so about as many loops as without the budget
  // (near-duplicates are judged in the merge, so a few more are verified).
  EXPECT_GE(budget_->verified, on_->verified);
  EXPECT_GE(double(budget_->accepted), 0.9 * double(on_->accepted));
  std::cout << "[ info ] budget " << kBudget << ": verified " << on_->verified << " -> "
            << budget_->verified << " (" << over_budget << " deferred), loops accepted "
            << on_->accepted << " -> " << budget_->accepted << "\n";
}

// server.map.closure_budget_swarm: the swarm's closures per window shared among
// the robots active. The first merge (one robot so far) gets all 2 x kBudget,
// every merge after it kBudget (both robots merged within active_robot_s).
TEST_F(DuplicateClosures, TheSwarmsBudgetIsSharedAmongTheRobotsActive) {
  ASSERT_TRUE(on_ && swarm_);
  std::map<KeyframeKey, std::size_t> first_seen;
  std::map<std::size_t, int> own;  // verified in their own merge, per merge
  int over_budget = 0;
  for (const Seen& s : swarm_->attempts) {
    first_seen.emplace(s.query, s.merge);
    if (s.status == LoopStatus::kSkippedBudget) ++over_budget;
    else if (s.status != LoopStatus::kSkippedDuplicate && first_seen[s.query] == s.merge) ++own[s.merge];
  }
  int above_share = 0;
  for (const auto& [merge, n] : own) {
    EXPECT_LE(n, 2 * kBudget) << "merge " << merge;
    above_share += n > kBudget;
  }
  EXPECT_LE(above_share, 1) << "only the first robot's first merge, alone, may verify more than kBudget";
  EXPECT_GT(over_budget, 0);
  EXPECT_EQ(swarm_->merged, 2);
  EXPECT_GE(double(swarm_->accepted), 0.9 * double(on_->accepted));
  std::cout << "[ info ] swarm budget " << 2 * kBudget << " over 2 robots: " << over_budget
            << " deferred, loops accepted " << on_->accepted << " -> " << swarm_->accepted << "\n";
}

// A checkpoint holds the closures the budget deferred: a server restored from
// it verifies them and ends with the loops of the one that never stopped.
TEST_F(DuplicateClosures, DeferredClosuresSurviveACheckpoint) {
  ASSERT_TRUE(fx_);
  ServerParams params;
  params.map.duplicate_neighbours = 2;
  params.map.duplicate_min_pair_loops = 6;
  params.map.closure_budget = kBudget;
  auto a = Server::create(params, HERMES_SOURCE_DIR);
  ASSERT_TRUE(a.ok()) << a.error();
  double now = 0;
  for (std::size_t r = 0; r < fx_->agents[0].frames.size() || r < fx_->agents[1].frames.size(); ++r)
    for (const auto& agent : fx_->agents) {
      if (r >= agent.frames.size()) continue;
      (*a)->onFrame(agent.frames[r].data(), agent.frames[r].size(), nullptr, now += 1);
      (*a)->process(now, 1);  // merges only: every closure over the budget waits
    }
  const std::size_t waiting = (*a)->deferredClosures();
  ASSERT_GT(waiting, 0u);
  auto b = Server::create(params, HERMES_SOURCE_DIR);
  ASSERT_TRUE(b.ok()) << b.error();
  ASSERT_TRUE((*b)->loadState((*a)->saveState()));
  EXPECT_EQ((*b)->deferredClosures(), waiting);
  for (Server* s : {a->get(), b->get()}) {
    double t = now;
    for (int idle = 0; idle < 1000 && s->deferredClosures() > 0; ++idle) s->process(t += 1, -1);
    EXPECT_EQ(s->deferredClosures(), 0u);
    EXPECT_EQ(s->counters().merge_errors, 0u) << s->counters().last_error;
  }
  EXPECT_GT((*a)->mapManager().loopsAccepted(), 0u);
  EXPECT_EQ((*b)->mapManager().loopsAccepted(), (*a)->mapManager().loopsAccepted());
  std::cout << "[ info ] " << waiting << " closures deferred at the checkpoint; loops accepted "
            << (*a)->mapManager().loopsAccepted() << " (uninterrupted) / "
            << (*b)->mapManager().loopsAccepted() << " (restored)\n";
}

TEST(DuplicateClosuresParams, NegativeIsRejected) {
  MapManagerParams p;
  p.duplicate_neighbours = -1;
  EXPECT_FALSE(p.validate().ok());
  p.duplicate_neighbours = 0;
  EXPECT_TRUE(p.validate().ok());
  p.duplicate_min_pair_loops = -1;
  EXPECT_FALSE(p.validate().ok());
  p.duplicate_min_pair_loops = 0;
  p.closure_budget = -1;
  EXPECT_FALSE(p.validate().ok());
  p.closure_budget = 0;
  p.closure_budget_swarm = -1;
  EXPECT_FALSE(p.validate().ok());
  p.closure_budget_swarm = 0;
  p.active_robot_s = 0;
  EXPECT_FALSE(p.validate().ok());
  p.active_robot_s = 15;
  p.closure_budget_min_robots = 0;
  EXPECT_FALSE(p.validate().ok());
  p.closure_budget_min_robots = 9;
  p.deferred_closures = -1;
  EXPECT_FALSE(p.validate().ok());
}

}  // namespace
}  // namespace server
}  // namespace hermes
