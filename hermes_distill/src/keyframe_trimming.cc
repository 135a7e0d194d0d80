// Keyframe trimming: path-flow MILP (CBC) warm-started by a dynamic programme
// improved by local search; the whole call keeps to trim_time_limit_s.
#include "hermes/distill/keyframe_trimming.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <unordered_map>
#include <utility>

#include <CbcModel.hpp>
#include <CoinWarmStartBasis.hpp>
#include <OsiClpSolverInterface.hpp>

namespace hermes {
namespace distill {
namespace {

struct Arc {
  int a, b;
};

// Landmark groups by the (sorted) set of window keyframes observing them.
std::map<std::vector<int>, int> landmarkGroups(const Submap& w) {
  std::unordered_map<KeyframeId, int> idx;
  for (std::size_t j = 0; j < w.keyframes.size(); ++j) idx[w.keyframes[j].id] = static_cast<int>(j);
  std::map<std::vector<int>, int> groups;
  for (const Landmark& lm : w.landmarks) {
    std::vector<int> set;
    for (const Observation& ob : lm.observations) {
      auto it = idx.find(ob.keyframe);
      if (it != idx.end()) set.push_back(it->second);
    }
    std::sort(set.begin(), set.end());
    set.erase(std::unique(set.begin(), set.end()), set.end());
    if (!set.empty()) ++groups[set];
  }
  return groups;
}

// Best Σ s path 0 -> n-1 over arcs with at most max_nodes nodes; if none exists,
// the path with the fewest nodes. Returns kept indices; *relaxed if N was exceeded.
std::vector<int> dpPath(int n, const std::vector<Arc>& arcs, const std::vector<double>& s,
                        int max_nodes, bool* relaxed) {
  const double kNeg = -std::numeric_limits<double>::infinity();
  // dp[c][b]: best value of a path 0..b with c nodes; parent for backtracking.
  std::vector<std::vector<double>> dp(static_cast<std::size_t>(n + 1), std::vector<double>(static_cast<std::size_t>(n), kNeg));
  std::vector<std::vector<int>> parent(static_cast<std::size_t>(n + 1), std::vector<int>(static_cast<std::size_t>(n), -1));
  dp[1][0] = s[0];
  std::vector<std::vector<int>> incoming(static_cast<std::size_t>(n));
  for (const Arc& e : arcs) incoming[static_cast<std::size_t>(e.b)].push_back(e.a);
  for (int c = 2; c <= n; ++c)
    for (int b = 1; b < n; ++b)
      for (int a : incoming[static_cast<std::size_t>(b)])
        if (dp[c - 1][a] > kNeg && dp[c - 1][a] + s[b] > dp[c][b]) {
          dp[c][b] = dp[c - 1][a] + s[b];
          parent[c][b] = a;
        }
  int best_c = -1;
  for (int c = 2; c <= std::min(n, max_nodes); ++c)
    if (dp[c][n - 1] > kNeg && (best_c < 0 || dp[c][n - 1] > dp[best_c][n - 1])) best_c = c;
  *relaxed = false;
  if (best_c < 0) {
    *relaxed = true;
    for (int c = 2; c <= n && best_c < 0; ++c)
      if (dp[c][n - 1] > kNeg) best_c = c;
  }
  std::vector<int> path;
  for (int b = n - 1, c = best_c; b >= 0 && c >= 1; b = parent[c][b], --c) {
    path.push_back(b);
    if (b == 0) break;
  }
  std::reverse(path.begin(), path.end());
  return path;
}

// The MILP in CSC form. Columns: y_j (n), z_e (arcs), then one ε per coverage
// row. Rows: Σ y <= N; flow out of v (v != last) and into v (v != first);
// coverage. y_first = y_last = 1, so a group seen by at most two keyframes has a
// linear slack ε = need − Σ y (folded into the y costs) and a group holding both
// ends is always covered; only groups of >= 3 keyframes keep a row, and groups
// with the same interior keyframes and the same remaining need share one row
// (their λ·count costs add: an exact reduction).
struct TrimModel {
  int n = 0, n_arc = 0, n_int = 0, n_slack = 0, ncols = 0, nrows = 0, first_cover_row = 0;
  std::vector<char> arc;                       // n×n, arc[a*n+b]
  std::vector<std::vector<int>> cover_rows_of; // per keyframe, coverage row offsets k
  std::vector<double> cover_need, cover_cost;  // per coverage row
  std::vector<CoinBigIndex> colstart;
  std::vector<int> index;
  std::vector<double> value, lb, ub, obj, rlb, rub;

  bool isArc(int a, int b) const { return arc[static_cast<std::size_t>(a * n + b)] != 0; }

  std::vector<double> columnsOf(const std::vector<int>& path, const std::vector<Arc>& arcs) const {
    std::vector<double> x(static_cast<std::size_t>(ncols), 0.0);
    std::vector<double> cover(static_cast<std::size_t>(n_slack), 0.0);
    for (int j : path) {
      x[static_cast<std::size_t>(j)] = 1.0;
      for (int k : cover_rows_of[static_cast<std::size_t>(j)]) cover[static_cast<std::size_t>(k)] += 1.0;
    }
    for (std::size_t k = 1; k < path.size(); ++k)
      for (int e = 0; e < n_arc; ++e)
        if (arcs[static_cast<std::size_t>(e)].a == path[k - 1] && arcs[static_cast<std::size_t>(e)].b == path[k])
          x[static_cast<std::size_t>(n + e)] = 1.0;
    for (int k = 0; k < n_slack; ++k)
      x[static_cast<std::size_t>(n_int + k)] =
          std::max(0.0, cover_need[static_cast<std::size_t>(k)] - cover[static_cast<std::size_t>(k)]);
    return x;
  }
};

TrimModel buildTrimModel(int n, const std::vector<Arc>& arcs, const std::vector<double>& s,
                         const std::map<std::vector<int>, int>& groups, int N, const DistillParams& params) {
  TrimModel m;
  m.n = n;
  m.n_arc = static_cast<int>(arcs.size());
  m.n_int = n + m.n_arc;
  m.arc.assign(static_cast<std::size_t>(n * n), 0);
  for (const Arc& e : arcs) m.arc[static_cast<std::size_t>(e.a * n + e.b)] = 1;
  m.obj.assign(static_cast<std::size_t>(m.n_int), 0.0);
  for (int j = 0; j < n; ++j) m.obj[static_cast<std::size_t>(j)] = -s[static_cast<std::size_t>(j)];
  auto out_row = [&](int v) { return 1 + v; };                  // v in [0, n-2]
  auto in_row = [&](int v) { return 1 + (n - 1) + (v - 1); };   // v in [1, n-1]
  m.first_cover_row = 1 + 2 * (n - 1);
  m.cover_rows_of.resize(static_cast<std::size_t>(n));
  std::map<std::pair<std::vector<int>, int>, int> row_of;  // (interior set, need) -> k
  for (const auto& [set, count] : groups) {
    const int need = std::min<int>(2, static_cast<int>(set.size()));
    std::vector<int> interior;
    for (int j : set)
      if (j != 0 && j != n - 1) interior.push_back(j);
    const int rest = need - (static_cast<int>(set.size()) - static_cast<int>(interior.size()));
    if (rest <= 0) continue;  // always covered
    if (set.size() <= 2) {    // ε = need − Σ y: linear
      for (int j : set) m.obj[static_cast<std::size_t>(j)] -= params.trim_lambda * count;
      continue;
    }
    auto [it, added] = row_of.emplace(std::make_pair(interior, rest), static_cast<int>(m.cover_need.size()));
    if (added) {
      for (int j : interior) m.cover_rows_of[static_cast<std::size_t>(j)].push_back(it->second);
      m.cover_need.push_back(rest);
      m.cover_cost.push_back(0.0);
    }
    m.cover_cost[static_cast<std::size_t>(it->second)] += params.trim_lambda * count;
  }
  m.n_slack = static_cast<int>(m.cover_need.size());
  m.ncols = m.n_int + m.n_slack;
  m.nrows = m.first_cover_row + m.n_slack;
  m.rlb.assign(static_cast<std::size_t>(m.first_cover_row), 0.0);
  m.rub = m.rlb;
  m.rlb[0] = -COIN_DBL_MAX;
  m.rub[0] = N;
  for (int k = 0; k < m.n_slack; ++k) {
    m.rlb.push_back(m.cover_need[static_cast<std::size_t>(k)]);
    m.rub.push_back(COIN_DBL_MAX);
  }
  m.lb.assign(static_cast<std::size_t>(m.ncols), 0.0);
  m.ub.assign(static_cast<std::size_t>(m.ncols), 1.0);
  m.lb[0] = 1.0;
  m.lb[static_cast<std::size_t>(n - 1)] = 1.0;
  m.obj.resize(static_cast<std::size_t>(m.ncols), 0.0);
  m.colstart.assign(static_cast<std::size_t>(m.ncols) + 1, 0);
  auto put = [&](int row, double v) {
    m.index.push_back(row);
    m.value.push_back(v);
  };
  for (int j = 0; j < n; ++j) {
    m.colstart[static_cast<std::size_t>(j)] = static_cast<CoinBigIndex>(m.index.size());
    put(0, 1.0);
    if (j != n - 1) put(out_row(j), -1.0);
    if (j != 0) put(in_row(j), -1.0);
    for (int k : m.cover_rows_of[static_cast<std::size_t>(j)]) put(m.first_cover_row + k, 1.0);
  }
  for (int e = 0; e < m.n_arc; ++e) {
    m.colstart[static_cast<std::size_t>(n + e)] = static_cast<CoinBigIndex>(m.index.size());
    put(out_row(arcs[static_cast<std::size_t>(e)].a), 1.0);
    put(in_row(arcs[static_cast<std::size_t>(e)].b), 1.0);
  }
  for (int k = 0; k < m.n_slack; ++k) {
    const std::size_t c = static_cast<std::size_t>(m.n_int + k);
    m.colstart[c] = static_cast<CoinBigIndex>(m.index.size());
    put(m.first_cover_row + k, 1.0);
    m.obj[c] = m.cover_cost[static_cast<std::size_t>(k)];
    m.ub[c] = m.cover_need[static_cast<std::size_t>(k)];
  }
  m.colstart[static_cast<std::size_t>(m.ncols)] = static_cast<CoinBigIndex>(m.index.size());
  return m;
}

// Local search on the MILP objective (coverage included) from a feasible path:
// drop, insert or replace one keyframe while the chain stays an arc path with
// <= N nodes; first improvement, until none improves or the deadline.
std::vector<int> improvePath(const TrimModel& m, std::vector<int> path, int N,
                             std::chrono::steady_clock::time_point deadline) {
  std::vector<int> cover(static_cast<std::size_t>(m.n_slack), 0);
  // Change of the objective when keyframe j enters (+1) or leaves (-1); applies it.
  auto toggle = [&](int j, int dir) {
    double d = dir * m.obj[static_cast<std::size_t>(j)];
    for (int k : m.cover_rows_of[static_cast<std::size_t>(j)]) {
      int& c = cover[static_cast<std::size_t>(k)];
      const double need = m.cover_need[static_cast<std::size_t>(k)];
      const double before = std::max(0.0, need - c);
      c += dir;
      d += m.cover_cost[static_cast<std::size_t>(k)] * (std::max(0.0, need - c) - before);
    }
    return d;
  };
  for (int j : path) toggle(j, +1);
  const double kEps = 1e-12;
  for (bool improved = true; improved && std::chrono::steady_clock::now() < deadline;) {
    improved = false;
    for (std::size_t i = 1; i + 1 < path.size() && !improved; ++i) {  // drop
      if (!m.isArc(path[i - 1], path[i + 1])) continue;
      if (toggle(path[i], -1) < -kEps) {
        path.erase(path.begin() + static_cast<std::ptrdiff_t>(i));
        improved = true;
      } else {
        toggle(path[i], +1);
      }
    }
    for (std::size_t i = 0; i + 1 < path.size() && !improved && static_cast<int>(path.size()) < N; ++i)
      for (int j = path[i] + 1; j < path[i + 1] && !improved; ++j) {  // insert
        if (!m.isArc(path[i], j) || !m.isArc(j, path[i + 1])) continue;
        if (toggle(j, +1) < -kEps) {
          path.insert(path.begin() + static_cast<std::ptrdiff_t>(i + 1), j);
          improved = true;
        } else {
          toggle(j, -1);
        }
      }
    for (std::size_t i = 1; i + 1 < path.size() && !improved; ++i)
      for (int j = path[i - 1] + 1; j < path[i + 1] && !improved; ++j) {  // replace
        if (j == path[i] || !m.isArc(path[i - 1], j) || !m.isArc(j, path[i + 1])) continue;
        const double d = toggle(path[i], -1) + toggle(j, +1);
        if (d < -kEps) {
          path[i] = j;
          improved = true;
        } else {
          toggle(j, -1);
          toggle(path[i], +1);
        }
      }
  }
  return path;
}

double separation(const SE3& Ta, const SE3& Tb, const DistillParams& params) {
  return params.trim_w_rot * rotationAngle(Ta.rotation().transpose() * Tb.rotation()) +
         params.trim_w_trans * (Ta.translation() - Tb.translation()).norm();
}

}  // namespace

double windowMotion(const Submap& w, const DistillParams& params) {
  double m = 0;
  for (std::size_t j = 1; j < w.keyframes.size(); ++j)
    m += separation(w.keyframes[j - 1].T_A_C, w.keyframes[j].T_A_C, params);
  return m;
}

int surplusKeyframeCap(const Submap& w, const DistillParams& params) {
  double n = 0;
  if (params.motion_keyframe_spacing > 0)
    n = std::ceil(windowMotion(w, params) / params.motion_keyframe_spacing);
  if (params.tracked_keyframe_fraction > 0)  // (- 1e-9: 0.55 x 20 is 11.000000000000002)
    n = std::max(n, std::ceil(params.tracked_keyframe_fraction *
                              static_cast<double>(w.keyframes.size()) - 1e-9));
  return static_cast<int>(std::clamp<double>(n, params.max_keyframes, params.trouble_max_keyframes));
}

std::vector<double> keyframeSeparation(const Submap& w, const DistillParams& params) {
  const std::size_t n = w.keyframes.size();
  std::vector<double> s(n, 0.0);
  if (n < 2) return s;
  for (std::size_t a = 0; a < n; ++a) {
    double best = std::numeric_limits<double>::infinity();
    for (std::size_t b = 0; b < n; ++b) {
      if (a == b) continue;
      best = std::min(best, separation(w.keyframes[a].T_A_C, w.keyframes[b].T_A_C, params));
    }
    s[a] = best;
  }
  return s;
}

double trimObjective(const Submap& w, const std::vector<int>& kept, const DistillParams& params,
                     double* coverage_slack) {
  const std::vector<double> s = keyframeSeparation(w, params);
  std::vector<char> y(w.keyframes.size(), 0);
  double obj = 0;
  for (int j : kept) {
    y[static_cast<std::size_t>(j)] = 1;
    obj += s[static_cast<std::size_t>(j)];
  }
  double slack = 0;
  for (const auto& [set, count] : landmarkGroups(w)) {
    int covered = 0;
    for (int j : set) covered += y[static_cast<std::size_t>(j)];
    slack += count * std::max(0, std::min<int>(2, static_cast<int>(set.size())) - covered);
  }
  if (coverage_slack) *coverage_slack = slack;
  return obj - params.trim_lambda * slack;
}

TrimResult trimKeyframes(const Submap& w, int max_keyframes, const DistillParams& params) {
  const auto t0 = std::chrono::steady_clock::now();
  TrimResult r;
  const int n = static_cast<int>(w.keyframes.size());
  auto finish = [&](SolveStatus st) {
    std::sort(r.kept.begin(), r.kept.end());
    r.status = st;
    r.objective = trimObjective(w, r.kept, params, &r.coverage_slack);
    r.solve_time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return r;
  };
  const int N = std::max(2, max_keyframes);
  if (n <= 2 || N >= n) {
    for (int j = 0; j < n; ++j) r.kept.push_back(j);
    return finish(SolveStatus::kOptimal);
  }
  const std::vector<double> s = keyframeSeparation(w, params);
  const auto groups = landmarkGroups(w);
  // Shared landmarks of every keyframe pair, from the groups in one pass.
  std::vector<int> shared(static_cast<std::size_t>(n * n), 0);
  for (const auto& [set, count] : groups)
    for (std::size_t x = 0; x < set.size(); ++x)
      for (std::size_t y = x + 1; y < set.size(); ++y) shared[static_cast<std::size_t>(set[x] * n + set[y])] += count;
  std::vector<Arc> arcs;
  for (int a = 0; a < n; ++a)
    for (int b = a + 1; b < n; ++b)
      if (b == a + 1 || shared[static_cast<std::size_t>(a * n + b)] >= params.trim_min_shared) arcs.push_back({a, b});
  bool relaxed = false;
  const std::vector<int> dp = dpPath(n, arcs, s, N, &relaxed);
  if (relaxed) {
    r.kept = dp;
    return finish(SolveStatus::kInfeasibleRelaxed);
  }
  // The time limit covers the whole call: model building, the root LP and CBC.
  // Work limits (params.workLimits()): no deadline; the root LP's iterations and
  // CBC's nodes are bounded instead.
  const bool work = params.workLimits();
  const auto deadline =
      work ? std::chrono::steady_clock::time_point::max()
           : t0 + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                      std::chrono::duration<double>(params.trim_time_limit_s));
  auto remaining = [&] {
    if (work) return std::numeric_limits<double>::infinity();
    return std::chrono::duration<double>(deadline - std::chrono::steady_clock::now()).count();
  };
  const TrimModel m = buildTrimModel(n, arcs, s, groups, N, params);
  // Warm start and fallback: the DP path improved on the MILP objective itself.
  r.kept = improvePath(m, dp, N, deadline);
  if (remaining() <= 0) return finish(SolveStatus::kGreedyFallback);
  auto solver = std::make_unique<OsiClpSolverInterface>();
  solver->messageHandler()->setLogLevel(0);
  solver->loadProblem(m.ncols, m.nrows, m.colstart.data(), m.index.data(), m.value.data(), m.lb.data(),
                      m.ub.data(), m.obj.data(), m.rlb.data(), m.rub.data());
  for (int c = 0; c < m.n_int; ++c) solver->setInteger(c);
  // Root LP by Clp under the deadline: CBC's own clock does not cover its root LP
  // (60-200 ms on 22-29 keyframe windows).
  {  // Start Clp at the vertex of the improved path: y, z at their bounds, the ε
     // of uncovered rows basic. From the slack basis the root LP missed the
     // budget in 13 of 48 real cases, from here in 3.
    const std::vector<double> x = m.columnsOf(r.kept, arcs);
    CoinWarmStartBasis basis;
    basis.setSize(m.ncols, m.nrows);
    for (int c = 0; c < m.n_int; ++c)
      basis.setStructStatus(c, x[static_cast<std::size_t>(c)] > 0.5 ? CoinWarmStartBasis::atUpperBound : CoinWarmStartBasis::atLowerBound);
    for (int row = 0; row < m.nrows; ++row) basis.setArtifStatus(row, CoinWarmStartBasis::basic);
    for (int k = 0; k < m.n_slack; ++k) {
      if (x[static_cast<std::size_t>(m.n_int + k)] > 0.5) {
        basis.setStructStatus(m.n_int + k, CoinWarmStartBasis::basic);
        basis.setArtifStatus(m.first_cover_row + k, CoinWarmStartBasis::atUpperBound);
      } else {
        basis.setStructStatus(m.n_int + k, CoinWarmStartBasis::atLowerBound);
      }
    }
    solver->setWarmStart(&basis);
  }
  if (work) solver->getModelPtr()->setMaximumIterations(params.trim_max_lp_iterations);
  else solver->getModelPtr()->setMaximumWallSeconds(remaining());
  solver->initialSolve();
  // CBC's root (re-solve, rounding) is outside its clock and can take 5-10 ms:
  // with less than 30% of the budget left it would overrun.
  if (!solver->isProvenOptimal() || (!work && remaining() < 0.3 * params.trim_time_limit_s))
    return finish(SolveStatus::kGreedyFallback);
  auto model = std::make_unique<CbcModel>(*solver);
  {
    std::unique_ptr<CoinWarmStart> root(solver->getWarmStart());
    model->solver()->setWarmStart(root.get());
  }
  model->setLogLevel(0);
  model->messageHandler()->setLogLevel(0);
  model->solver()->messageHandler()->setLogLevel(0);
  model->setNumberStrong(0);  // strong branching (pseudo-cost initialisation included)
  model->setNumberBeforeTrust(0);  // ignores the time limit
  if (work) {
    model->setMaximumNodes(params.trim_max_nodes);
  } else {
    model->setUseElapsedTime(true);
    model->setMaximumSeconds(0.5 * remaining());  // checked between nodes only
  }
  {  // Incumbent: the improved path (feasible by construction, so no check LP).
    std::vector<double> start = m.columnsOf(r.kept, arcs);
    double o = 0;
    for (int c = 0; c < m.ncols; ++c) o += m.obj[static_cast<std::size_t>(c)] * start[static_cast<std::size_t>(c)];
    model->setBestSolution(start.data(), m.ncols, o, false);
  }
  const std::vector<int> fallback = r.kept;
  model->branchAndBound();
  const double* best = model->bestSolution();
  if (best == nullptr) return finish(SolveStatus::kGreedyFallback);
  r.kept.clear();
  for (int j = 0; j < n; ++j)
    if (best[j] > 0.5) r.kept.push_back(j);
  // Repair guard: the chain property holds by construction; verify anyway.
  bool ok = !r.kept.empty() && r.kept.front() == 0 && r.kept.back() == n - 1 &&
            static_cast<int>(r.kept.size()) <= N;
  for (std::size_t k = 1; ok && k < r.kept.size(); ++k) ok = m.isArc(r.kept[k - 1], r.kept[k]);
  if (!ok) {
    r.kept = fallback;
    return finish(SolveStatus::kGreedyFallback);
  }
  if (model->isProvenOptimal() && !model->isSecondsLimitReached() && !model->isNodeLimitReached())
    return finish(SolveStatus::kOptimal);
  return finish(work ? SolveStatus::kWorkLimited : SolveStatus::kTimeLimited);
}

}  // namespace distill
}  // namespace hermes
