// Landmark selection (DESIGN §3, Eq. 14 keep-form) behind one interface.
//
//   min Σ_i (1 + ε − v_i) x_i + λ₁ Σ_j ξ_j + λ₂ Σ_g φ_g
//   s.t. Σ_i A_ij x_i + ξ_j ≥ min(K, n_j)   per keyframe j
//        Σ_{i∈g} x_i + φ_g ≥ 1              per occupied grid cell g of every keyframe
//        Σ_i b_i x_i ≤ S_LM                 hard byte budget
//        x binary, ξ, φ ≥ 0
//
// Strategies: milp (CBC, warm-started from the greedy solution of the same
// objective), greedy_logdet (lazy greedy on f(S) = log det(δI + ΣΛ)), stability
// (MD_A: each keyframe's K most observed landmarks), anms (MD_B: each keyframe's
// K spatially best spread keypoints by adaptive non-maximal suppression), none
// (everything). Every strategy except none honours the byte budget; the
// heuristics stop adding once every keyframe has its min(K, n_j) landmarks.
#pragma once

#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "hermes/core/map_types.h"
#include "hermes/core/status.h"
#include "hermes/distill/params.h"
#include "hermes/distill/scores.h"

namespace hermes {
namespace distill {

/// One instance of Eq. 14; landmark i is the i-th landmark of the submap it was built from.
struct SelectionProblem {
  std::vector<LandmarkId> ids;              ///< landmark ids (empty for synthetic instances)
  std::vector<double> cost;                 ///< 1 + ε − v_i
  std::vector<double> bytes;                ///< b_i
  double budget = std::numeric_limits<double>::infinity();  ///< S_LM
  std::vector<std::vector<int>> kf_members; ///< landmarks seen by keyframe j
  std::vector<double> kf_demand;            ///< min(K, n_j)
  std::vector<std::vector<int>> cell_members;  ///< landmarks in occupied cell g
  double lambda_support = 2.0, lambda_grid = 1.5;
  int k = 0;
  double time_limit_s = 0;  ///< > 0 overrides the MILP selector's own time limit
  /// Optional selection (e.g. the previous coordinator round's) that the MILP
  /// also considers as its warm start; ignored when it does not fit the budget.
  std::vector<int> warm_start;
  // Data the heuristic strategies use.
  std::vector<double> q_s;
  std::vector<double> value;
  std::vector<Mat6> lambda;
  double delta = 1e-3;
  /// Per keyframe: (landmark index, keypoint pixel) for ANMS.
  std::vector<std::vector<std::pair<int, Vec2>>> kf_points;

  int size() const { return static_cast<int>(cost.size()); }
};

/// b_i = c_LM + c_obs · (observations of i in the submap's keyframes).
SelectionProblem buildSelectionProblem(const Submap& window, const LandmarkScores& scores, int k,
                                       double budget_bytes, double bytes_per_landmark,
                                       double bytes_per_observation, const DistillParams& params);

enum class SolveStatus {
  kOptimal,            ///< CBC proved optimality
  kTimeLimited,        ///< CBC stopped at its time limit with an incumbent (>= greedy)
  kWorkLimited,        ///< CBC stopped at its work limit (solver_limits work) with an incumbent
  kGreedyFallback,     ///< CBC had no usable incumbent: greedy selection returned
  kInfeasibleRelaxed,  ///< the budget is negative: nothing kept, all slack reported
  kHeuristic,          ///< a heuristic strategy (no optimality claim)
  kUnconstrained,      ///< strategy none: everything kept, budget ignored
};
const char* toString(SolveStatus s);

struct SelectionResult {
  SolveStatus status = SolveStatus::kHeuristic;
  std::vector<int> selected;               ///< indices into the problem, ascending
  std::vector<LandmarkId> selected_ids;    ///< ids of `selected` (when the problem has ids)
  double objective = 0;                    ///< Eq. 14 objective of `selected`
  double support_slack = 0;                ///< Σ ξ_j
  double grid_slack = 0;                   ///< Σ φ_g
  double bytes = 0;                        ///< Σ b_i of `selected`
  double solve_time_s = 0;
  double greedy_objective = 0;             ///< milp only: objective of its warm start
  double lower_bound = 0;                  ///< milp only: CBC's proven lower bound
};

/// Evaluates Eq. 14 for a selection (slacks at their optimal values).
double evaluateObjective(const SelectionProblem& p, const std::vector<int>& selected,
                         double* support_slack = nullptr, double* grid_slack = nullptr);

/// Lazy greedy on Eq. 14: the better of two passes, by objective decrease per
/// byte and by absolute decrease, adding what fits while the decrease is positive.
std::vector<int> greedyEq14(const SelectionProblem& p);

class LandmarkSelector {
 public:
  virtual ~LandmarkSelector() = default;
  virtual std::string name() const = 0;
  virtual SelectionResult select(const SelectionProblem& problem) const = 0;
};

/// milp | greedy_logdet | stability | anms | none; error names the unknown strategy.
Expected<std::unique_ptr<LandmarkSelector>> makeLandmarkSelector(const std::string& strategy,
                                                                 const DistillParams& params);

/// Fills objective, slacks and bytes of `r` from its selection (sorted).
void finaliseResult(const SelectionProblem& p, SelectionResult* r);

}  // namespace distill
}  // namespace hermes
