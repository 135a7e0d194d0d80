// Eq. 14 solved exactly with COIN-OR CBC (C++ API), warm-started from the
// greedy solution; falls back to the greedy selection when CBC has no usable
// incumbent. Solver objects live in unique_ptr owners.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>

#include <CbcModel.hpp>
#include <CbcStrategy.hpp>
#include <CoinPackedMatrix.hpp>
#include <CoinPackedVector.hpp>
#include <OsiClpSolverInterface.hpp>

#include "hermes/distill/selectors.h"

namespace hermes {
namespace distill {

MilpSelector::MilpSelector(double time_limit_s, bool warm_start, double rel_gap)
    : time_limit_s_(time_limit_s), warm_start_(warm_start), rel_gap_(rel_gap) {}

SelectionResult MilpSelector::select(const SelectionProblem& p) const {
  const auto t0 = std::chrono::steady_clock::now();
  SelectionResult r;
  auto done = [&](SolveStatus status) {
    r.status = status;
    finaliseResult(p, &r);
    r.solve_time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return r;
  };
  if (!(p.budget >= 0)) return done(SolveStatus::kInfeasibleRelaxed);

  const std::vector<int> greedy = greedyEq14(p);
  r.greedy_objective = evaluateObjective(p, greedy);
  const int n = p.size();
  if (n == 0) return done(SolveStatus::kOptimal);
  const int n_kf = static_cast<int>(p.kf_members.size());
  const int n_cell = static_cast<int>(p.cell_members.size());
  const int ncols = n + n_kf + n_cell;
  const bool has_budget = std::isfinite(p.budget);

  std::vector<double> collb(static_cast<std::size_t>(ncols), 0.0), colub(static_cast<std::size_t>(ncols), 1.0),
      obj(static_cast<std::size_t>(ncols), 0.0);
  for (int i = 0; i < n; ++i) {
    obj[static_cast<std::size_t>(i)] = p.cost[static_cast<std::size_t>(i)];
    if (has_budget && p.bytes[static_cast<std::size_t>(i)] > p.budget) colub[static_cast<std::size_t>(i)] = 0.0;
  }
  for (int j = 0; j < n_kf; ++j) {
    obj[static_cast<std::size_t>(n + j)] = p.lambda_support;
    colub[static_cast<std::size_t>(n + j)] = p.kf_demand[static_cast<std::size_t>(j)];
  }
  for (int g = 0; g < n_cell; ++g) obj[static_cast<std::size_t>(n + n_kf + g)] = p.lambda_grid;

  CoinPackedMatrix rows(false, 0, 0);
  rows.setDimensions(0, ncols);
  std::vector<double> rowlb, rowub;
  const double inf = COIN_DBL_MAX;
  for (int j = 0; j < n_kf; ++j) {
    CoinPackedVector row;
    for (int i : p.kf_members[static_cast<std::size_t>(j)]) row.insert(i, 1.0);
    row.insert(n + j, 1.0);
    rows.appendRow(row);
    rowlb.push_back(p.kf_demand[static_cast<std::size_t>(j)]);
    rowub.push_back(inf);
  }
  for (int g = 0; g < n_cell; ++g) {
    CoinPackedVector row;
    for (int i : p.cell_members[static_cast<std::size_t>(g)]) row.insert(i, 1.0);
    row.insert(n + n_kf + g, 1.0);
    rows.appendRow(row);
    rowlb.push_back(1.0);
    rowub.push_back(inf);
  }
  if (has_budget) {
    CoinPackedVector row;
    for (int i = 0; i < n; ++i) row.insert(i, p.bytes[static_cast<std::size_t>(i)]);
    rows.appendRow(row);
    rowlb.push_back(-inf);
    rowub.push_back(p.budget);
  }

  auto solver = std::make_unique<OsiClpSolverInterface>();
  solver->messageHandler()->setLogLevel(0);
  solver->loadProblem(rows, collb.data(), colub.data(), obj.data(), rowlb.data(), rowub.data());
  for (int i = 0; i < n; ++i) solver->setInteger(i);
  auto model = std::make_unique<CbcModel>(*solver);
  model->setLogLevel(0);
  model->messageHandler()->setLogLevel(0);
  model->solver()->messageHandler()->setLogLevel(0);
  model->setUseElapsedTime(true);
  model->setMaximumSeconds(std::max(1e-4, p.time_limit_s > 0 ? p.time_limit_s : time_limit_s_));
  model->setAllowableGap(1e-7);
  model->setAllowableFractionGap(rel_gap_);
  CbcStrategyDefault strategy(1, 5, 0, 0);  // root cuts + default heuristics, no preprocessing
  model->setStrategy(strategy);

  if (warm_start_) {
    std::vector<double> start(static_cast<std::size_t>(ncols), 0.0);
    std::vector<double> support(static_cast<std::size_t>(n_kf), 0.0);
    for (int i : greedy) start[static_cast<std::size_t>(i)] = 1.0;
    for (int j = 0; j < n_kf; ++j) {
      double s = 0;
      for (int i : p.kf_members[static_cast<std::size_t>(j)]) s += start[static_cast<std::size_t>(i)];
      start[static_cast<std::size_t>(n + j)] = std::max(0.0, p.kf_demand[static_cast<std::size_t>(j)] - s);
    }
    for (int g = 0; g < n_cell; ++g) {
      bool covered = false;
      for (int i : p.cell_members[static_cast<std::size_t>(g)]) covered = covered || start[static_cast<std::size_t>(i)] > 0.5;
      start[static_cast<std::size_t>(n + n_kf + g)] = covered ? 0.0 : 1.0;
    }
    model->setBestSolution(start.data(), ncols, r.greedy_objective, true);
  }
  model->branchAndBound();

  const double* best = model->bestSolution();
  r.lower_bound = model->getBestPossibleObjValue();
  std::vector<int> chosen;
  bool usable = best != nullptr;
  if (usable) {
    double bytes = 0;
    for (int i = 0; i < n; ++i)
      if (best[i] > 0.5) {
        chosen.push_back(i);
        bytes += p.bytes[static_cast<std::size_t>(i)];
      }
    if (has_budget && bytes > p.budget + 1e-6) usable = false;  // never trust blindly
  }
  if (!usable) {
    r.selected = greedy;
    return done(SolveStatus::kGreedyFallback);
  }
  r.selected = chosen;
  if (evaluateObjective(p, chosen) > r.greedy_objective + 1e-9) r.selected = greedy;
  const bool optimal = model->isProvenOptimal() && !model->isSecondsLimitReached();
  return done(optimal ? SolveStatus::kOptimal : SolveStatus::kTimeLimited);
}

}  // namespace distill
}  // namespace hermes
