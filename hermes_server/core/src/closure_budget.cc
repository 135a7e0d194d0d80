#include "hermes/server/closure_budget.h"

#include <algorithm>

namespace hermes {
namespace server {

TrajectoryPair makeTrajectoryPair(TrajectoryId a, TrajectoryId b) {
  return a < b ? TrajectoryPair{a, b} : TrajectoryPair{b, a};
}

TrajectoryPair pairOf(const KeyframeKey& a, const KeyframeKey& b) {
  return makeTrajectoryPair({a.agent, a.session}, {b.agent, b.session});
}

std::map<TrajectoryPair, int> acceptedLoopsPerPair(const std::vector<LoopEdge>& loops) {
  std::map<TrajectoryPair, int> accepted;
  for (const LoopEdge& e : loops)
    if (e.accepted) ++accepted[pairOf(e.a, e.b)];
  return accepted;
}

std::vector<char> chooseWithinBudget(const std::vector<TrajectoryPair>& pairs,
                                     const std::map<TrajectoryPair, int>& accepted, int budget) {
  const std::size_t n = pairs.size();
  if (budget <= 0 || n <= static_cast<std::size_t>(budget)) return std::vector<char>(n, 1);
  // Closures of each pair in the order proposed; pairs in order of first closure.
  std::vector<TrajectoryPair> order;
  std::map<TrajectoryPair, std::vector<std::size_t>> of_pair;
  for (std::size_t i = 0; i < n; ++i) {
    auto& list = of_pair[pairs[i]];
    if (list.empty()) order.push_back(pairs[i]);
    list.push_back(i);
  }
  const auto loops = [&](const TrajectoryPair& p) {
    auto it = accepted.find(p);
    return it == accepted.end() ? 0 : it->second;
  };
  std::stable_sort(order.begin(), order.end(),
                   [&](const TrajectoryPair& a, const TrajectoryPair& b) { return loops(a) < loops(b); });
  std::vector<char> chosen(n, 0);
  int left = budget;
  for (std::size_t round = 0; left > 0; ++round) {
    bool any = false;
    for (const TrajectoryPair& p : order) {
      const auto& list = of_pair[p];
      if (round >= list.size()) continue;
      any = true;
      chosen[list[round]] = 1;
      if (--left == 0) break;
    }
    if (!any) break;
  }
  return chosen;
}

}  // namespace server
}  // namespace hermes
