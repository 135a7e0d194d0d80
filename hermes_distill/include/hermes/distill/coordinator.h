// Bandwidth coordinator (DESIGN §3, Eq. 17): byte budget, byte model, and the
// choice of (N_KF, K).
//
//   S = η · B̂ · Δt − backlog_bytes
// (B̂ is the rate the agent plans with: the bandwidth monitor's estimate, times
// uplink.monitor.probe_factor while it probes for more.)
//   bytes ≈ c0 + c_KF·N_KF + c_obs·(kept observations) + c_LM·(kept landmarks)
// The c· are refitted by ridge-regularised least squares (towards the configured
// prior, so few samples stay well posed) over the most recent real encodings.
// The kept landmarks and observations for a given (N_KF, K) come from the
// window's track statistics (predictKept) times per-strategy ratios that a
// KeptModel learns online from what the selector really kept: the MILP keeps
// only what the support demand asks for (long tracks, ~0.3x the structural
// estimate's landmarks on real windows), the greedy strategies keep more.
#pragma once

#include <array>
#include <cmath>
#include <deque>
#include <string>

#include "hermes/core/map_types.h"
#include "hermes/distill/params.h"

namespace hermes {
namespace distill {

struct CoordinatorInput {
  double bandwidth_Bps = 0;   ///< B̂, estimated uplink rate [bytes/s]
  double backlog_bytes = 0;   ///< bytes still unacknowledged in the buffer
  int loop_closures = 0;      ///< loops found so far (α rule)
  /// B̂ comes from acknowledged data (not the start guess), nothing sent is still
  /// unacknowledged and the window carries no deferred one (a deferral means the
  /// link is tight): only then may spare budget carry loop keypoints.
  bool link_keeps_up = false;
  /// No acknowledgement has measured the link yet (B̂ is the start guess): a
  /// window that would have carried loop keypoints on a link that keeps up
  /// holds them back (DistillResult::held_back) for later keyframe extensions.
  bool link_unmeasured = false;
  /// Time the window stands for [s]; 0 = one window period (window.period_s). A
  /// window carrying deferred ones stands for all their periods: the link had
  /// that long for it (else the floor, which grows with the span, never fits).
  double period_s = 0;
  /// The server has placed this robot in the global map (a global pose came
  /// back). While it has not, its windows keep up to trouble_max_keyframes
  /// keyframes (distill.unplaced_aware): more places where a loop can tie it in.
  bool placed = true;
};

/// Eq. 17 budget η B̂ Δt − backlog (may be negative when the backlog exceeds what the link carries).
double budgetBytes(const DistillParams& params, const CoordinatorInput& in);

class ByteModel {
 public:
  explicit ByteModel(const DistillParams& params);
  double predict(double n_kf, double observations, double n_landmarks) const;
  /// Records one real encoding and refits the coefficients.
  void addSample(double n_kf, double observations, double n_landmarks, double bytes);
  double c0() const { return c_[0]; }
  double cKf() const { return c_[1]; }
  double cObs() const { return c_[2]; }
  double cLm() const { return c_[3]; }
  std::size_t samples() const { return samples_.size(); }

 private:
  void refit();
  std::array<double, 4> prior_;
  std::array<double, 4> c_;
  std::deque<std::array<double, 5>> samples_;  // n_kf, obs, lm, 1, bytes
};

struct CoordinatorPlan {
  bool defer = false;
  std::string reason;     ///< why deferred
  int n_kf = 0;
  int k = 0;
  double predicted_bytes = 0;
};

/// Smallest number of keyframes the floor allows for this window
/// (max(2, ceil(min_keyframe_rate · span)), at most the window's keyframes).
int keyframeFloor(const Submap& window, const DistillParams& params);

/// Predicted (kept landmarks, kept observations) of a window distilled to
/// N keyframes with K landmarks each, from the window's track statistics.
void predictKept(const Submap& window, int n_kf, int k, double* landmarks, double* observations);

/// What one strategy keeps relative to predictKept: ratios r_lm, r_obs, learnt
/// from the selections it made (log-ratio running mean, the prior r = 1 weighing
/// half a sample, forgetting beyond the last 6 samples; each ratio bounded to
/// [kMinRatio, kMaxRatio]). A selection the byte budget cut short only shows a
/// lower bound of what the demand asks for, so it can raise a ratio, never lower it.
class KeptModel {
 public:
  static constexpr double kMinRatio = 0.1;
  static constexpr double kMaxRatio = 3.0;

  /// predictKept(window, n_kf, k) scaled by the learnt ratios.
  void predict(const Submap& window, int n_kf, int k, double* landmarks, double* observations) const;
  /// Records what the selector kept from `window` trimmed to n_kf keyframes with
  /// K = k; budget_bound: the byte budget, not the demand, limited the selection.
  void addSample(const Submap& window, int n_kf, int k, double landmarks, double observations,
                 bool budget_bound);
  double landmarkRatio() const { return std::exp(log_ratio_[0]); }
  double observationRatio() const { return std::exp(log_ratio_[1]); }
  std::size_t samples() const { return samples_; }

 private:
  std::array<double, 2> log_ratio_{0.0, 0.0};  // landmarks, observations
  std::size_t samples_ = 0;
};

/// K for a window already trimmed to its keyframes (the trimming may keep fewer
/// than planned, and the trimmed tracks are what the selector sees): the largest
/// K in [k_min, k_max] predicted within plan_fill · S, else within S, else k_min
/// (the selector's hard budget then decides). predicted_bytes is filled.
CoordinatorPlan chooseK(const Submap& trimmed, double budget, const ByteModel& model,
                        const KeptModel& kept, const DistillParams& params);

/// Chooses (N_KF, K) so that the predicted size is at most plan_fill · S: the most keyframes in [floor,
/// min(max_keyframes, n)] that carry K = k_pref, then the largest K up to k_max
/// at that N_KF; if even the floor cannot carry k_pref, the floor with the
/// largest K down to k_min (against S itself when plan_fill · S is too little).
/// Defers when nothing at or above the floor fits S.
/// `surplus_max_keyframes` (a fast window's surplusKeyframeCap): keyframes above
/// max_keyframes, up to this many, are kept only from the budget's surplus, when
/// every one of them still carries K = k_max within plan_fill · S; they never
/// take landmarks from the others (whole MH at 0.5 Mbit/s: 2.70 -> 2.06 cm; at 2
/// and 10 Mbit/s the fast windows had the surplus and nothing changed).
CoordinatorPlan planDistillation(const Submap& window, double budget, const ByteModel& model,
                                 const KeptModel& kept, const DistillParams& params,
                                 int surplus_max_keyframes = 0);

}  // namespace distill
}  // namespace hermes
