// Eq. 14 instance construction, evaluation and the greedy baseline used as the
// MILP's warm start and fallback.
#include <algorithm>
#include <cmath>
#include <map>
#include <queue>
#include <unordered_map>

#include "hermes/distill/landmark_selection.h"

namespace hermes {
namespace distill {

const char* toString(SolveStatus s) {
  switch (s) {
    case SolveStatus::kOptimal: return "optimal";
    case SolveStatus::kTimeLimited: return "time_limited";
    case SolveStatus::kWorkLimited: return "work_limited";
    case SolveStatus::kGreedyFallback: return "greedy_fallback";
    case SolveStatus::kInfeasibleRelaxed: return "infeasible_relaxed";
    case SolveStatus::kHeuristic: return "heuristic";
    case SolveStatus::kUnconstrained: return "unconstrained";
  }
  return "unknown";
}

SelectionProblem buildSelectionProblem(const Submap& window, const LandmarkScores& scores, int k,
                                       double budget_bytes, double bytes_per_landmark,
                                       double bytes_per_observation, const DistillParams& params) {
  SelectionProblem p;
  const std::size_t n = window.landmarks.size();
  p.k = k;
  p.budget = budget_bytes;
  p.lambda_support = params.lambda_support;
  p.lambda_grid = params.lambda_grid;
  p.delta = params.delta;
  p.q_s = scores.q_s;
  p.value = scores.value;
  p.lambda = scores.lambda;
  p.cost.resize(n);
  p.bytes.resize(n);
  std::unordered_map<KeyframeId, std::size_t> kf_index;
  for (std::size_t j = 0; j < window.keyframes.size(); ++j) kf_index[window.keyframes[j].id] = j;
  p.kf_members.assign(window.keyframes.size(), {});
  p.kf_points.assign(window.keyframes.size(), {});
  std::vector<std::map<int, std::vector<int>>> cells(window.keyframes.size());
  for (std::size_t i = 0; i < n; ++i) {
    const Landmark& lm = window.landmarks[i];
    p.ids.push_back(lm.id);
    p.cost[i] = 1.0 + params.epsilon - scores.value[i];
    int obs = 0;
    for (const Observation& ob : lm.observations) {
      auto it = kf_index.find(ob.keyframe);
      if (it == kf_index.end()) continue;
      const Keyframe& kf = window.keyframes[it->second];
      if (ob.keypoint >= kf.keypoints.size() || kf.camera_id >= window.cameras.size()) continue;
      auto& members = p.kf_members[it->second];
      if (!members.empty() && members.back() == static_cast<int>(i)) continue;  // duplicate
      ++obs;
      members.push_back(static_cast<int>(i));
      const Keypoint& kp = kf.keypoints[ob.keypoint];
      p.kf_points[it->second].emplace_back(static_cast<int>(i), Vec2(kp.u, kp.v));
      const PinholeIntrinsics& cam = window.cameras[kf.camera_id];
      const double cw = std::max(1.0, static_cast<double>(cam.width)) / params.grid_cols;
      const double ch = std::max(1.0, static_cast<double>(cam.height)) / params.grid_rows;
      const int cx = std::clamp(static_cast<int>(kp.u / cw), 0, params.grid_cols - 1);
      const int cy = std::clamp(static_cast<int>(kp.v / ch), 0, params.grid_rows - 1);
      cells[it->second][cy * params.grid_cols + cx].push_back(static_cast<int>(i));
    }
    p.bytes[i] = bytes_per_landmark + bytes_per_observation * obs;
  }
  p.kf_demand.resize(window.keyframes.size());
  for (std::size_t j = 0; j < window.keyframes.size(); ++j) {
    p.kf_demand[j] = std::min<double>(k, static_cast<double>(p.kf_members[j].size()));
    for (auto& [cell, members] : cells[j]) p.cell_members.push_back(std::move(members));
  }
  return p;
}

double evaluateObjective(const SelectionProblem& p, const std::vector<int>& selected,
                         double* support_slack, double* grid_slack) {
  std::vector<char> x(p.cost.size(), 0);
  double obj = 0;
  for (int i : selected) {
    x[static_cast<std::size_t>(i)] = 1;
    obj += p.cost[static_cast<std::size_t>(i)];
  }
  double xi = 0, phi = 0;
  for (std::size_t j = 0; j < p.kf_members.size(); ++j) {
    double support = 0;
    for (int i : p.kf_members[j]) support += x[static_cast<std::size_t>(i)];
    xi += std::max(0.0, p.kf_demand[j] - support);
  }
  for (const auto& members : p.cell_members) {
    bool covered = false;
    for (int i : members) covered = covered || x[static_cast<std::size_t>(i)];
    if (!covered) phi += 1.0;
  }
  if (support_slack) *support_slack = xi;
  if (grid_slack) *grid_slack = phi;
  return obj + p.lambda_support * xi + p.lambda_grid * phi;
}

void finaliseResult(const SelectionProblem& p, SelectionResult* r) {
  std::sort(r->selected.begin(), r->selected.end());
  r->objective = evaluateObjective(p, r->selected, &r->support_slack, &r->grid_slack);
  r->bytes = 0;
  r->selected_ids.clear();
  for (int i : r->selected) {
    r->bytes += p.bytes[static_cast<std::size_t>(i)];
    if (static_cast<std::size_t>(i) < p.ids.size()) r->selected_ids.push_back(p.ids[static_cast<std::size_t>(i)]);
  }
}

namespace {

// One lazy greedy pass: by gain per byte (per_byte) or by absolute gain.
std::vector<int> greedyPass(const SelectionProblem& p, bool per_byte) {
  const std::size_t n = p.cost.size();
  std::vector<int> selected;
  if (!(p.budget >= 0)) return selected;
  // Membership lists landmark -> keyframes / cells.
  std::vector<std::vector<int>> in_kf(n), in_cell(n);
  for (std::size_t j = 0; j < p.kf_members.size(); ++j)
    for (int i : p.kf_members[j]) in_kf[static_cast<std::size_t>(i)].push_back(static_cast<int>(j));
  for (std::size_t g = 0; g < p.cell_members.size(); ++g)
    for (int i : p.cell_members[g]) in_cell[static_cast<std::size_t>(i)].push_back(static_cast<int>(g));
  std::vector<double> support(p.kf_members.size(), 0.0);
  std::vector<char> covered(p.cell_members.size(), 0);
  auto gain = [&](std::size_t i) {
    double g = -p.cost[i];
    for (int j : in_kf[i]) g += support[static_cast<std::size_t>(j)] + 1.0 <= p.kf_demand[static_cast<std::size_t>(j)] + 1e-9 ? p.lambda_support : 0.0;
    for (int c : in_cell[i]) g += covered[static_cast<std::size_t>(c)] ? 0.0 : p.lambda_grid;
    return g;
  };
  // Gains only shrink as the selection grows (capped coverage), so a stale
  // priority is an upper bound: lazy evaluation is exact.
  using Entry = std::pair<double, int>;  // (gain per byte, index)
  std::priority_queue<Entry> heap;
  for (std::size_t i = 0; i < n; ++i) {
    const double g = gain(i);
    if (g > 0) heap.emplace(per_byte ? g / std::max(p.bytes[i], 1e-9) : g, static_cast<int>(i));
  }
  double used = 0;
  std::vector<char> taken(n, 0);
  while (!heap.empty()) {
    const auto [ratio, idx] = heap.top();
    heap.pop();
    const std::size_t i = static_cast<std::size_t>(idx);
    if (taken[i] || used + p.bytes[i] > p.budget) continue;
    const double g = gain(i);
    if (g <= 0) continue;
    const double r = per_byte ? g / std::max(p.bytes[i], 1e-9) : g;
    if (!heap.empty() && r < heap.top().first - 1e-12) {
      heap.emplace(r, idx);
      continue;
    }
    taken[i] = 1;
    used += p.bytes[i];
    selected.push_back(idx);
    for (int j : in_kf[i]) support[static_cast<std::size_t>(j)] += 1.0;
    for (int c : in_cell[i]) covered[static_cast<std::size_t>(c)] = 1;
  }
  std::sort(selected.begin(), selected.end());
  return selected;
}

}  // namespace

std::vector<int> greedyEq14(const SelectionProblem& p) {
  // The better of the two classic knapsack greedy orders.
  std::vector<int> a = greedyPass(p, true);
  std::vector<int> b = greedyPass(p, false);
  return evaluateObjective(p, b) < evaluateObjective(p, a) ? b : a;
}

}  // namespace distill
}  // namespace hermes
