// Heuristic landmark selection strategies and the strategy factory.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>
#include <limits>
#include <queue>

#include "hermes/distill/selectors.h"

namespace hermes {
namespace distill {
namespace {

double secondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// Adds candidates in the given order while they fit the budget.
std::vector<int> fillBudget(const SelectionProblem& p, const std::vector<int>& order) {
  std::vector<int> out;
  double used = 0;
  for (int i : order) {
    const double b = p.bytes[static_cast<std::size_t>(i)];
    if (used + b > p.budget) continue;
    used += b;
    out.push_back(i);
  }
  return out;
}

// Per landmark: its best (smallest) rank among the keyframes' top-K lists;
// landmarks in no list get rank -1. Returns the landmarks ordered by rank.
std::vector<int> unionByRank(const SelectionProblem& p,
                             const std::vector<std::vector<int>>& per_kf_ranked) {
  std::vector<int> best(p.cost.size(), -1);
  for (std::size_t j = 0; j < per_kf_ranked.size(); ++j) {
    const int take = static_cast<int>(p.kf_demand[j]);
    for (int r = 0; r < take && r < static_cast<int>(per_kf_ranked[j].size()); ++r) {
      int& b = best[static_cast<std::size_t>(per_kf_ranked[j][static_cast<std::size_t>(r)])];
      b = b < 0 ? r : std::min(b, r);
    }
  }
  std::vector<int> order;
  for (std::size_t i = 0; i < best.size(); ++i)
    if (best[i] >= 0) order.push_back(static_cast<int>(i));
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    const int ra = best[static_cast<std::size_t>(a)], rb = best[static_cast<std::size_t>(b)];
    if (ra != rb) return ra < rb;
    return p.q_s[static_cast<std::size_t>(a)] > p.q_s[static_cast<std::size_t>(b)];
  });
  return order;
}

double strength(const SelectionProblem& p, int i) {
  return p.q_s[static_cast<std::size_t>(i)] + 1e-3 * p.value[static_cast<std::size_t>(i)];
}

}  // namespace

SelectionResult GreedyLogDetSelector::select(const SelectionProblem& p) const {
  const auto t0 = std::chrono::steady_clock::now();
  SelectionResult r;
  r.status = SolveStatus::kHeuristic;
  const std::size_t n = p.cost.size();
  std::vector<std::vector<int>> in_kf(n);
  for (std::size_t j = 0; j < p.kf_members.size(); ++j)
    for (int i : p.kf_members[j]) in_kf[static_cast<std::size_t>(i)].push_back(static_cast<int>(j));
  std::vector<double> support(p.kf_members.size(), 0.0);
  auto useful = [&](std::size_t i) {
    for (int j : in_kf[i])
      if (support[static_cast<std::size_t>(j)] < p.kf_demand[static_cast<std::size_t>(j)]) return true;
    return false;
  };
  Mat6 M = p.delta * Mat6::Identity();
  double f = logDetSpd(M);
  using Entry = std::pair<double, int>;
  std::priority_queue<Entry> heap;
  for (std::size_t i = 0; i < n; ++i) {
    const double g = logDetSpd(M + p.lambda[i]) - f;
    heap.emplace(g / std::max(p.bytes[i], 1e-9), static_cast<int>(i));
  }
  double used = 0;
  while (!heap.empty() && p.budget >= 0) {
    const auto [ratio, idx] = heap.top();
    heap.pop();
    const std::size_t i = static_cast<std::size_t>(idx);
    if (used + p.bytes[i] > p.budget || !useful(i)) continue;
    const double fi = logDetSpd(M + p.lambda[i]);
    const double rnew = (fi - f) / std::max(p.bytes[i], 1e-9);
    if (!heap.empty() && rnew < heap.top().first - 1e-12) {  // stale: re-queue (submodular)
      heap.emplace(rnew, idx);
      continue;
    }
    M += p.lambda[i];
    f = fi;
    used += p.bytes[i];
    r.selected.push_back(idx);
    for (int j : in_kf[i]) support[static_cast<std::size_t>(j)] += 1.0;
  }
  finaliseResult(p, &r);
  r.solve_time_s = secondsSince(t0);
  return r;
}

SelectionResult StabilitySelector::select(const SelectionProblem& p) const {
  const auto t0 = std::chrono::steady_clock::now();
  SelectionResult r;
  r.status = SolveStatus::kHeuristic;
  std::vector<std::vector<int>> ranked = p.kf_members;
  for (auto& list : ranked)
    std::stable_sort(list.begin(), list.end(),
                     [&](int a, int b) { return strength(p, a) > strength(p, b); });
  std::vector<int> order = unionByRank(p, ranked);
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return strength(p, a) > strength(p, b); });
  if (p.budget >= 0) r.selected = fillBudget(p, order);
  finaliseResult(p, &r);
  r.solve_time_s = secondsSince(t0);
  return r;
}

SelectionResult AnmsSelector::select(const SelectionProblem& p) const {
  const auto t0 = std::chrono::steady_clock::now();
  SelectionResult r;
  r.status = SolveStatus::kHeuristic;
  std::vector<std::vector<int>> ranked(p.kf_points.size());
  for (std::size_t j = 0; j < p.kf_points.size(); ++j) {
    const auto& pts = p.kf_points[j];
    // Sort by strength; a point's radius is its distance to the nearest stronger one.
    std::vector<std::size_t> order(pts.size());
    std::iota(order.begin(), order.end(), 0);
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
      return strength(p, pts[a].first) > strength(p, pts[b].first);
    });
    std::vector<double> radius(pts.size(), std::numeric_limits<double>::infinity());
    for (std::size_t a = 1; a < order.size(); ++a) {
      const Vec2& pa = pts[order[a]].second;
      double best = std::numeric_limits<double>::infinity();
      for (std::size_t b = 0; b < a; ++b) best = std::min(best, (pts[order[b]].second - pa).squaredNorm());
      radius[order[a]] = best;
    }
    std::vector<std::size_t> by_radius = order;
    std::stable_sort(by_radius.begin(), by_radius.end(),
                     [&](std::size_t a, std::size_t b) { return radius[a] > radius[b]; });
    for (std::size_t k : by_radius) ranked[j].push_back(pts[k].first);
  }
  if (p.budget >= 0) r.selected = fillBudget(p, unionByRank(p, ranked));
  finaliseResult(p, &r);
  r.solve_time_s = secondsSince(t0);
  return r;
}

SelectionResult KeepAllSelector::select(const SelectionProblem& p) const {
  SelectionResult r;
  r.status = SolveStatus::kUnconstrained;
  r.selected.resize(p.cost.size());
  std::iota(r.selected.begin(), r.selected.end(), 0);
  finaliseResult(p, &r);
  return r;
}

Expected<std::unique_ptr<LandmarkSelector>> makeLandmarkSelector(const std::string& strategy,
                                                                 const DistillParams& params) {
  std::unique_ptr<LandmarkSelector> s;
  if (strategy == "milp") {
    s = std::make_unique<MilpSelector>(params.milp_time_limit_s, params.milp_warm_start,
                                       params.milp_rel_gap,
                                       params.workLimits() ? params.milp_max_nodes : 0);
  } else if (strategy == "greedy_logdet") {
    s = std::make_unique<GreedyLogDetSelector>();
  } else if (strategy == "stability") {
    s = std::make_unique<StabilitySelector>();
  } else if (strategy == "anms") {
    s = std::make_unique<AnmsSelector>();
  } else if (strategy == "none") {
    s = std::make_unique<KeepAllSelector>();
  } else {
    return Error{"unknown landmark selection strategy '" + strategy +
                 "' (expected milp | greedy_logdet | stability | anms | none)"};
  }
  return Expected<std::unique_ptr<LandmarkSelector>>(std::move(s));
}

}  // namespace distill
}  // namespace hermes
