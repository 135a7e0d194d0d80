// chooseWithinBudget (closure_budget.h): at most the budget, pairs with fewer
// accepted loops first, round robin over pairs, each pair's closures in order.
#include <gtest/gtest.h>

#include "hermes/server/closure_budget.h"

namespace hermes {
namespace server {
namespace {

const TrajectoryId kA{0, 1}, kB{1, 1}, kC{2, 1}, kD{3, 1};

std::vector<std::size_t> chosenIndices(const std::vector<char>& flags) {
  std::vector<std::size_t> out;
  for (std::size_t i = 0; i < flags.size(); ++i)
    if (flags[i]) out.push_back(i);
  return out;
}

TEST(ClosureBudget, PairIsSymmetric) {
  EXPECT_EQ(makeTrajectoryPair(kA, kB), makeTrajectoryPair(kB, kA));
  EXPECT_NE(makeTrajectoryPair(kA, kB), makeTrajectoryPair(kA, kC));
}

TEST(ClosureBudget, NoBudgetOrFewClosuresKeepsAll) {
  const std::vector<TrajectoryPair> pairs(5, makeTrajectoryPair(kA, kB));
  EXPECT_EQ(chosenIndices(chooseWithinBudget(pairs, {}, 0)).size(), 5u);
  EXPECT_EQ(chosenIndices(chooseWithinBudget(pairs, {}, 5)).size(), 5u);
  EXPECT_EQ(chosenIndices(chooseWithinBudget(pairs, {}, 9)).size(), 5u);
  EXPECT_TRUE(chooseWithinBudget({}, {}, 3).empty());
}

TEST(ClosureBudget, UntiedPairsFirstThenRoundRobin) {
  const TrajectoryPair ab = makeTrajectoryPair(kA, kB), ac = makeTrajectoryPair(kA, kC),
                       cd = makeTrajectoryPair(kC, kD);
  // Proposed: four closures A-B (tied by 200 loops), then two A-C (tied by 5),
  // then two C-D (not tied).
  const std::vector<TrajectoryPair> pairs{ab, ab, ab, ab, ac, ac, cd, cd};
  const std::map<TrajectoryPair, int> accepted{{ab, 200}, {ac, 5}};
  // Budget 1: the untied pair's first closure.
  EXPECT_EQ(chosenIndices(chooseWithinBudget(pairs, accepted, 1)), (std::vector<std::size_t>{6}));
  // Budget 3: one per pair, fewest loops first (C-D, A-C, A-B).
  EXPECT_EQ(chosenIndices(chooseWithinBudget(pairs, accepted, 3)), (std::vector<std::size_t>{0, 4, 6}));
  // Budget 5: a second round, again C-D before A-C.
  EXPECT_EQ(chosenIndices(chooseWithinBudget(pairs, accepted, 5)),
            (std::vector<std::size_t>{0, 4, 5, 6, 7}));
  // Budget 7: the busy pair takes what the others leave, in its own order.
  EXPECT_EQ(chosenIndices(chooseWithinBudget(pairs, accepted, 7)),
            (std::vector<std::size_t>{0, 1, 2, 4, 5, 6, 7}));
}

TEST(ClosureBudget, EqualLoopsKeepTheProposedOrder) {
  const TrajectoryPair ab = makeTrajectoryPair(kA, kB), cd = makeTrajectoryPair(kC, kD);
  const std::vector<TrajectoryPair> pairs{cd, ab, cd, ab};
  EXPECT_EQ(chosenIndices(chooseWithinBudget(pairs, {}, 2)), (std::vector<std::size_t>{0, 1}));
  EXPECT_EQ(chosenIndices(chooseWithinBudget(pairs, {}, 3)), (std::vector<std::size_t>{0, 1, 2}));
}

}  // namespace
}  // namespace server
}  // namespace hermes
