#include "distill_fixture.h"

#include <cstdio>
#include <cstdlib>
#include <limits>
#include <map>
#include <memory>

namespace hermes {
namespace distill {
namespace testing {

const SyntheticScene& sceneFromFile(const std::string& sequence) {
  static std::map<std::string, std::unique_ptr<SyntheticScene>> cache;
  auto it = cache.find(sequence);
  if (it != cache.end()) return *it->second;
  SyntheticWindowParams params;
  params.seed = 11;
  auto s = makeSceneFromTum(sequence, params);
  if (!s) {
    std::fprintf(stderr, "test fixture: %s\n", s.error().c_str());
    std::abort();
  }
  return *cache.emplace(sequence, std::make_unique<SyntheticScene>(std::move(s.value()))).first->second;
}

SyntheticWindow windowFromFile(const std::string& path, double t_start, std::uint64_t seq) {
  auto w = sceneFromFile(path).window(t_start, seq);
  if (!w) {
    std::fprintf(stderr, "test fixture: %s\n", w.error().c_str());
    std::abort();
  }
  return std::move(w.value());
}

SelectionProblem randomProblem(std::mt19937_64& rng, int n, int n_kf, int k,
                               double budget_fraction) {
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  SelectionProblem p;
  p.k = k;
  p.lambda_support = 1.0 + 2.0 * uni(rng);
  p.lambda_grid = 0.5 + 2.0 * uni(rng);
  p.kf_members.assign(static_cast<std::size_t>(n_kf), {});
  p.kf_points.assign(static_cast<std::size_t>(n_kf), {});
  std::vector<std::map<int, std::vector<int>>> cells(static_cast<std::size_t>(n_kf));
  double total = 0;
  for (int i = 0; i < n; ++i) {
    const double v = uni(rng);
    p.value.push_back(v);
    p.cost.push_back(1.05 - v);
    int obs = 0;
    for (int j = 0; j < n_kf; ++j) {
      if (uni(rng) > 0.45) continue;
      ++obs;
      p.kf_members[static_cast<std::size_t>(j)].push_back(i);
      const Vec2 uv(uni(rng) * 752, uni(rng) * 480);
      p.kf_points[static_cast<std::size_t>(j)].emplace_back(i, uv);
      cells[static_cast<std::size_t>(j)][static_cast<int>(uv.x() / 376) + 2 * static_cast<int>(uv.y() / 240)].push_back(i);
    }
    p.q_s.push_back(obs);
    p.bytes.push_back(64 + 40 * obs);
    total += p.bytes.back();
    Eigen::Matrix<double, 3, 6> W = Eigen::Matrix<double, 3, 6>::Random();
    p.lambda.push_back(W.transpose() * W * (obs + 1));
  }
  for (int j = 0; j < n_kf; ++j) {
    p.kf_demand.push_back(std::min<double>(k, static_cast<double>(p.kf_members[static_cast<std::size_t>(j)].size())));
    for (auto& [c, m] : cells[static_cast<std::size_t>(j)]) p.cell_members.push_back(m);
  }
  p.budget = budget_fraction * total;
  return p;
}

double bruteForce(const SelectionProblem& p, std::vector<int>* best) {
  const int n = p.size();
  double best_obj = std::numeric_limits<double>::infinity();
  for (std::uint32_t mask = 0; mask < (1u << n); ++mask) {
    std::vector<int> sel;
    double bytes = 0;
    for (int i = 0; i < n; ++i)
      if (mask & (1u << i)) {
        sel.push_back(i);
        bytes += p.bytes[static_cast<std::size_t>(i)];
      }
    if (bytes > p.budget) continue;
    const double obj = evaluateObjective(p, sel);
    if (obj < best_obj) {
      best_obj = obj;
      if (best) *best = sel;
    }
  }
  return best_obj;
}

}  // namespace testing
}  // namespace distill
}  // namespace hermes
