// Landmark selection: MILP optimality against brute force, constraint/slack
// bookkeeping, the hard byte budget for every strategy, the CBC time-limit path.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>

#include "distill_fixture.h"
#include "hermes/distill/keyframe_trimming.h"
#include "hermes/distill/selectors.h"

namespace hermes {
namespace distill {
namespace {

const std::vector<std::string> kStrategies = {"milp", "greedy_logdet", "stability", "anms", "none"};

TEST(Selection, FactoryKnowsEveryStrategyAndRejectsOthers) {
  for (const auto& s : kStrategies) {
    auto sel = makeLandmarkSelector(s, DistillParams{});
    ASSERT_TRUE(sel.ok()) << s;
    EXPECT_EQ((*sel)->name(), s);
  }
  auto bad = makeLandmarkSelector("gurobi", DistillParams{});
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().find("gurobi"), std::string::npos);
}

TEST(Selection, MilpMatchesBruteForceOnSmallInstances) {
  std::mt19937_64 rng(42);
  MilpSelector milp(5.0, true);
  int strictly_better_than_greedy = 0;
  for (int trial = 0; trial < 40; ++trial) {
    const int n = 6 + trial % 11;  // 6..16 landmarks
    const SelectionProblem p = testing::randomProblem(rng, n, 2 + trial % 4, 1 + trial % 5,
                                                      0.2 + 0.15 * (trial % 5));
    std::vector<int> best;
    const double opt = testing::bruteForce(p, &best);
    const SelectionResult r = milp.select(p);
    EXPECT_EQ(r.status, SolveStatus::kOptimal) << "trial " << trial;
    EXPECT_NEAR(r.objective, opt, 1e-6) << "trial " << trial << " n " << n;
    EXPECT_LE(r.bytes, p.budget + 1e-9);
    EXPECT_LE(r.objective, r.greedy_objective + 1e-9);
    EXPECT_LE(r.lower_bound, opt + 1e-6) << "the bound is in Eq. 14 terms";
    if (r.objective < r.greedy_objective - 1e-6) ++strictly_better_than_greedy;
  }
  EXPECT_GT(strictly_better_than_greedy, 0) << "greedy never suboptimal: instances too easy";
}

TEST(Selection, ConstraintsHoldOrTheirSlackIsReported) {
  std::mt19937_64 rng(7);
  for (int trial = 0; trial < 30; ++trial) {
    const SelectionProblem p = testing::randomProblem(rng, 40 + trial, 5, 6, 0.1 + 0.03 * trial);
    for (const auto& s : kStrategies) {
      const SelectionResult r = (*makeLandmarkSelector(s, DistillParams{}))->select(p);
      std::vector<char> x(static_cast<std::size_t>(p.size()), 0);
      double bytes = 0;
      for (int i : r.selected) {
        x[static_cast<std::size_t>(i)] = 1;
        bytes += p.bytes[static_cast<std::size_t>(i)];
      }
      double xi = 0, phi = 0;
      for (std::size_t j = 0; j < p.kf_members.size(); ++j) {
        int support = 0;
        for (int i : p.kf_members[j]) support += x[static_cast<std::size_t>(i)];
        xi += std::max(0.0, p.kf_demand[j] - support);
      }
      for (const auto& cell : p.cell_members)
        phi += std::none_of(cell.begin(), cell.end(), [&](int i) { return x[static_cast<std::size_t>(i)]; });
      EXPECT_NEAR(r.support_slack, xi, 1e-9) << s;
      EXPECT_NEAR(r.grid_slack, phi, 1e-9) << s;
      EXPECT_NEAR(r.bytes, bytes, 1e-6) << s;
      if (s != "none") {
        EXPECT_LE(bytes, p.budget + 1e-9) << s << " trial " << trial;
      }
    }
  }
}

TEST(Selection, NoStrategyEverExceedsTheByteBudgetOnRealWindows) {
  std::mt19937_64 rng(99);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  DistillParams params;
  params.milp_time_limit_s = 0.05;
  int windows = 0;
  for (const std::string seq : {"MH_01_easy", "V1_01_easy"}) {
    for (double t : {12.0, 47.0, 81.0, 120.0}) {
      const SyntheticWindow w = testing::window(seq, t);
      const LandmarkScores sc = computeScores(w.submap, w.hint, 0, params);
      for (int b = 0; b < 3; ++b) {
        const int k = 10 + static_cast<int>(uni(rng) * 100);
        SelectionProblem p = buildSelectionProblem(w.submap, sc, k, 0, 64, 40, params);
        double all = 0;
        for (double x : p.bytes) all += x;
        p.budget = all * uni(rng) * 0.6;
        for (const auto& s : {"milp", "greedy_logdet", "stability", "anms"}) {
          const SelectionResult r = (*makeLandmarkSelector(s, params))->select(p);
          EXPECT_LE(r.bytes, p.budget) << s << " " << seq << " t=" << t;
          EXPECT_GT(r.selected.size(), 0u) << s;
        }
      }
      ++windows;
    }
  }
  EXPECT_EQ(windows, 8);
}

TEST(Selection, NegativeBudgetIsReportedAsInfeasibleRelaxed) {
  std::mt19937_64 rng(1);
  SelectionProblem p = testing::randomProblem(rng, 10, 3, 3, 0.5);
  p.budget = -5;
  const SelectionResult r = MilpSelector(1.0, true).select(p);
  EXPECT_EQ(r.status, SolveStatus::kInfeasibleRelaxed);
  EXPECT_TRUE(r.selected.empty());
  EXPECT_GT(r.support_slack, 0);
}

/// Eq. 14 on a real MH_01 window (K = 60) with 40 % of its landmarks' bytes.
SelectionProblem realWindowProblem(const SyntheticWindow& w, const DistillParams& params) {
  const LandmarkScores sc = computeScores(w.submap, w.hint, 0, params);
  SelectionProblem p = buildSelectionProblem(w.submap, sc, 60, 0, 64, 40, params);
  double all = 0;
  for (double x : p.bytes) all += x;
  p.budget = 0.4 * all;
  return p;
}

TEST(Selection, MilpImprovesOnGreedyOnARealWindow) {
  DistillParams params;
  const SyntheticWindow w = testing::window("MH_01_easy", 60.0);
  const SelectionProblem p = realWindowProblem(w, params);
  const SelectionResult r = MilpSelector(2.0, true).select(p);
  EXPECT_EQ(r.status, SolveStatus::kOptimal);
  ASSERT_EQ(r.selected_ids.size(), r.selected.size());
  for (std::size_t k = 0; k < r.selected.size(); ++k)
    EXPECT_EQ(r.selected_ids[k], w.submap.landmarks[static_cast<std::size_t>(r.selected[k])].id);
  EXPECT_LE(r.objective, r.greedy_objective + 1e-9);
  EXPECT_NEAR(r.greedy_objective, evaluateObjective(p, greedyEq14(p)), 1e-9);
  // Every heuristic is feasible for Eq. 14, so none beats the optimum.
  for (const auto& s : {"greedy_logdet", "stability", "anms"})
    EXPECT_GE((*makeLandmarkSelector(s, params))->select(p).objective, r.objective - 1e-6) << s;
}

TEST(Selection, TimeLimitReturnsGreedyOrBetterWithItsStatus) {
  DistillParams params;
  // A full-size window with a large K: far too big to solve in a microsecond.
  const SyntheticWindow w = testing::window("V1_01_easy", 30.0);
  const LandmarkScores sc = computeScores(w.submap, w.hint, 0, params);
  SelectionProblem p = buildSelectionProblem(w.submap, sc, 120, 0, 64, 40, params);
  double all = 0;
  for (double x : p.bytes) all += x;
  p.budget = 0.35 * all;
  const std::vector<int> greedy = greedyEq14(p);
  const double greedy_obj = evaluateObjective(p, greedy);
  for (bool warm : {true, false}) {
    const SelectionResult r = MilpSelector(1e-6, warm).select(p);
    EXPECT_TRUE(r.status == SolveStatus::kTimeLimited || r.status == SolveStatus::kGreedyFallback)
        << toString(r.status);
    EXPECT_LE(r.bytes, p.budget);
    EXPECT_LE(r.objective, greedy_obj + 1e-9);
    if (r.status == SolveStatus::kGreedyFallback) {
      EXPECT_EQ(r.selected, greedy);
    }
  }
}

TEST(Selection, WorkLimitsIgnoreTheClockAndRepeatExactly) {
  SelectionProblem p = realWindowProblem(testing::window("MH_01_easy", 60.0), DistillParams());
  const SelectionResult timed = MilpSelector(2.0, true).select(p);
  ASSERT_EQ(timed.status, SolveStatus::kOptimal);
  // A node limit, no time limit: a time limit of 1 ns is not read at all.
  const SelectionResult work = MilpSelector(1e-9, true, 0.0, 1000000).select(p);
  EXPECT_EQ(work.status, SolveStatus::kOptimal);
  EXPECT_NEAR(work.objective, timed.objective, 1e-9);
  // One node: stopped by the work limit (or solved at the root), the same
  // selection on every call, greedy or better, within the budget.
  p.time_limit_s = 1e-9;
  const SelectionResult one = MilpSelector(1e-9, true, 0.0, 1).select(p);
  EXPECT_TRUE(one.status == SolveStatus::kWorkLimited || one.status == SolveStatus::kOptimal)
      << toString(one.status);
  EXPECT_LE(one.bytes, p.budget);
  EXPECT_LE(one.objective, one.greedy_objective + 1e-9);
  for (int rep = 0; rep < 3; ++rep) EXPECT_EQ(MilpSelector(1e-9, true, 0.0, 1).select(p).selected, one.selected);
}

TEST(Selection, MilpStartsFromABetterHintAndIgnoresOneOverBudget) {
  std::mt19937_64 rng(5);
  for (int trial = 0; trial < 10; ++trial) {
    SelectionProblem p = testing::randomProblem(rng, 8 + trial, 3, 4, 0.4);
    std::vector<int> best;
    const double opt = testing::bruteForce(p, &best);
    // The optimum as a hint under a 1-microsecond limit: CBC cannot prove
    // anything, so the result is the hint (it beats or ties greedy).
    p.warm_start = best;
    const SelectionResult hinted = MilpSelector(1e-6, true).select(p);
    EXPECT_NEAR(hinted.objective, opt, 1e-9) << "trial " << trial;
    EXPECT_LE(hinted.bytes, p.budget + 1e-9);
    // A hint over the budget is never returned.
    p.warm_start.resize(static_cast<std::size_t>(p.size()));
    for (int i = 0; i < p.size(); ++i) p.warm_start[static_cast<std::size_t>(i)] = i;
    const SelectionResult r = MilpSelector(1e-6, true).select(p);
    EXPECT_LE(r.bytes, p.budget + 1e-9) << "trial " << trial;
  }
}

TEST(Selection, KeepAllKeepsEverything) {
  std::mt19937_64 rng(2);
  const SelectionProblem p = testing::randomProblem(rng, 30, 4, 5, 0.1);
  const SelectionResult r = KeepAllSelector().select(p);
  EXPECT_EQ(r.status, SolveStatus::kUnconstrained);
  EXPECT_EQ(static_cast<int>(r.selected.size()), p.size());
}

}  // namespace
}  // namespace distill
}  // namespace hermes
