// The distillation facade the agent calls every Δt: coordinator -> keyframe
// trimming -> scores -> landmark selection -> encode-size check (<= max_rounds,
// shrinking K) -> distilled submap + report, or "defer" (keep it in the buffer).
//
// Modes:
//  * strategy none: raw streaming; the whole window (odometry edges added), no
//    trimming, no budget (report.over_budget says whether it exceeded S).
//  * coordinator off: N_KF = max_keyframes, K = fixed_k, no byte budget.
//  * coordinator on: S from Eq. 17, (N_KF, K) from the byte model and the kept
//    model (both learnt from this distiller's earlier rounds; the plan aims at
//    plan_fill · S), the selector's hard budget S_LM = S − c0 − c_KF·N_kept; if
//    the real encoded size exceeds S, K and S_LM shrink by the overshoot ratio
//    and the selection reruns; if it fits below fill_accept · S and K < k_max,
//    K grows by S/size (at most ×2) and the larger selection is kept if it
//    still fits. At most max_rounds selections;
//    if none fits, the least valuable landmarks are dropped until the real size
//    fits (status suffix "+repaired"); only if that fails is the window deferred.
#pragma once

#include <cstddef>
#include <functional>
#include <memory>
#include <optional>
#include <string>

#include "hermes/core/config.h"
#include "hermes/core/map_types.h"
#include "hermes/distill/coordinator.h"
#include "hermes/distill/keyframe_trimming.h"
#include "hermes/distill/landmark_selection.h"
#include "hermes/distill/params.h"
#include "hermes/distill/scores.h"

namespace hermes {
namespace distill {

/// Returns the exact encoded (wire) size of a submap in bytes.
using EncodedSizeFn = std::function<std::size_t(const Submap&)>;

struct DistillReport {
  bool ok = true;              ///< false: the window was malformed (see error)
  std::string error;
  bool deferred = false;       ///< keep the window in the buffer, send later
  std::string defer_reason;
  std::string strategy;
  std::string selection_status;  ///< toString(SolveStatus) of the kept round (+"+repaired")
  std::string trim_status;
  int n_kf_in = 0, n_kf = 0;
  int n_lm_in = 0, n_lm = 0;
  std::size_t observations = 0;
  int k = 0;                   ///< landmarks per keyframe targeted
  int loop_keypoints = 0;      ///< keypoints per keyframe sent without a landmark (spare budget)
  int extension_keyframes = 0;   ///< earlier keyframes extended (extendWithHeldBack)
  int extension_keypoints = 0;   ///< keypoints per extended keyframe (at most)
  double budget_bytes = 0;     ///< S (infinite with the coordinator off)
  double bytes_planned = 0;    ///< coordinator's prediction for its (N_KF, K) plan
  double bytes_predicted = 0;  ///< byte model of the sent submap
  std::size_t bytes_actual = 0;  ///< encoder's size (0 without a size function)
  bool over_budget = false;
  bool trouble = false;        ///< the window was in trouble (inTrouble): more keyframes and budget
  bool unplaced = false;       ///< the robot was not in the global map yet: more keyframes
  int rounds = 0;
  double objective = 0, greedy_objective = 0, support_slack = 0, grid_slack = 0;
  double alpha = 0, beta = 0;
  double time_trim_ms = 0, time_scores_ms = 0, time_select_ms = 0, time_encode_ms = 0,
         time_total_ms = 0;
};

struct DistillResult {
  Submap submap;
  DistillReport report;
  /// Set when the window was planned on an unmeasured link and would have
  /// carried loop keypoints on one that keeps up: its kept keyframes with the
  /// keypoints it did not send (heldBackKeypoints), for extendWithHeldBack.
  std::optional<Submap> held_back;
};

/// A window where the agent's tracking was in trouble: lost (within the window,
/// or a keyframe of the window follows a loss) or weak on at least
/// params.trouble_weak_frames frames. Always false with trouble_aware off.
bool inTrouble(const Submap& window, const TrackingHealth& health, const DistillParams& params);

/// Whether the distiller has a second selector for where the link binds
/// (params.tight_strategy): coordinator on, not raw streaming, and a tight
/// strategy other than the main one.
bool usesTightSelector(const DistillParams& params);

class Distiller {
 public:
  /// size_fn may be empty: the byte model's prediction is used instead.
  Distiller(const DistillParams& params, EncodedSizeFn size_fn);
  ~Distiller();

  /// Fails when params are invalid or name an unknown strategy.
  static Expected<std::unique_ptr<Distiller>> create(const DistillParams& params,
                                                     EncodedSizeFn size_fn);

  DistillResult distill(const Submap& window, const MotionHint& hint,
                        const CoordinatorInput& input);

  /// Prepends keyframe extensions (see Submap) of an earlier window's held-back
  /// keypoints to a distilled window `r` (not deferred): up to
  /// distill.loop_keypoints per keyframe, within what is left of half the
  /// window's budget (the window's own loop keypoints come first). Call it only
  /// on a link that keeps up.
  void extendWithHeldBack(const Submap& held, DistillResult* r) const;

  const ByteModel& byteModel() const { return model_; }
  const KeptModel& keptModel() const { return kept_; }
  const DistillParams& params() const { return params_; }

 private:
  /// Once K reached k_max on a link that keeps up (CoordinatorInput::link_keeps_up):
  /// up to distill.loop_keypoints keypoints per keyframe without a landmark (what
  /// the server's loop closure matches), as many as fit in half the budget;
  /// `fit` is unchanged otherwise.
  void addLoopKeypoints(const Submap& trimmed, const std::vector<int>& selected, Submap* fit,
                        DistillReport* rep) const;
  /// Keypoints without a landmark on top of `*fit` within half the budget:
  /// `build(n)` makes the candidate with up to n per keyframe over `n_kf`
  /// keyframes; n halves once if the first candidate is too large. Returns the
  /// n taken (0: `*fit` unchanged).
  int spendSpareOnKeypoints(std::size_t n_kf, const std::function<Submap(std::size_t)>& build,
                            Submap* fit, DistillReport* rep) const;

  DistillParams params_;
  EncodedSizeFn size_fn_;
  std::unique_ptr<LandmarkSelector> selector_;
  std::unique_ptr<LandmarkSelector> tight_selector_;  ///< where the link binds (null: selector_)
  ByteModel model_;
  KeptModel kept_;
};

}  // namespace distill
}  // namespace hermes
