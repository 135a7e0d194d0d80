// The concrete landmark selection strategies (see landmark_selection.h).
#pragma once

#include "hermes/distill/landmark_selection.h"

namespace hermes {
namespace distill {

/// Eq. 14 with CBC; status optimal / time_limited / work_limited / greedy_fallback / infeasible_relaxed.
class MilpSelector : public LandmarkSelector {
 public:
  /// rel_gap: CBC stops once (incumbent − bound) <= rel_gap·|incumbent|; the
  /// result then counts as optimal (within that gap). 0 = prove exact optimality.
  /// max_nodes > 0: work limits instead of time (distill.solver_limits work):
  /// CBC stops after max_nodes branch-and-bound nodes and no clock is read, so
  /// the selection does not depend on the machine's load; time_limit_s is unused.
  MilpSelector(double time_limit_s, bool warm_start, double rel_gap = 0.0, int max_nodes = 0);
  std::string name() const override { return "milp"; }
  SelectionResult select(const SelectionProblem& problem) const override;

 private:
  double time_limit_s_;
  bool warm_start_;
  double rel_gap_;
  int max_nodes_;
};

/// Lazy greedy on f(S) = log det(δI + Σ Λ_l), by gain per byte, within the budget;
/// a landmark is only added while one of its keyframes is below min(K, n_j).
class GreedyLogDetSelector : public LandmarkSelector {
 public:
  std::string name() const override { return "greedy_logdet"; }
  SelectionResult select(const SelectionProblem& problem) const override;
};

/// MD_A: every keyframe's K most-observed landmarks, added most-observed first
/// while they fit the budget.
class StabilitySelector : public LandmarkSelector {
 public:
  std::string name() const override { return "stability"; }
  SelectionResult select(const SelectionProblem& problem) const override;
};

/// MD_B: per keyframe, adaptive non-maximal suppression over its keypoints
/// (strength q_s, ties by v); the K keypoints with the largest suppression radius
/// are kept; added best rank first while they fit the budget.
class AnmsSelector : public LandmarkSelector {
 public:
  std::string name() const override { return "anms"; }
  SelectionResult select(const SelectionProblem& problem) const override;
};

/// Keeps everything (raw streaming); the budget is ignored by definition.
class KeepAllSelector : public LandmarkSelector {
 public:
  std::string name() const override { return "none"; }
  SelectionResult select(const SelectionProblem& problem) const override;
};

}  // namespace distill
}  // namespace hermes
