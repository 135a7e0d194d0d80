// Keyframe trimming (DESIGN §3, Eq. 15–16 keep-form) and the submap surgery
// around distillation.
//
// sd(a,b) = w_R·angle(R_aᵀR_b) + w_T·‖t_a − t_b‖, s_j = min_{k≠j} sd(j,k).
//   max Σ_j s_j y_j − λ Σ_l ε_l
//   s.t. Σ_j y_j ≤ N_KF;  Σ_j E_lj y_j + ε_l ≥ min(2, obs_l);  y_first = y_last = 1;
//        consecutive kept keyframes share landmarks.
// Formulation: connectivity is exact, as a path through the window. Arc (a,b),
// a < b, exists when keyframes a and b share >= trim_min_shared landmarks, or
// b = a + 1 (the tracker linked them). Binary z_ab with flow conservation
// Σ_b z_ab = y_a (a ≠ last), Σ_a z_ab = y_b (b ≠ first) forces the kept keyframes
// to form one chain of arcs from first to last, so every consecutive kept pair is
// an arc. Landmarks with the same set of observing keyframes share one ε (weighted
// by their count); since the first and last keyframe are always kept, a group seen
// by <= 2 keyframes has the linear ε = need − Σ y (folded into the y costs) and a
// group holding both ends is always covered, so only groups of >= 3 keyframes keep
// a row (groups with the same interior keyframes and need share it). CBC solves it
// warm-started from a dynamic programme (best Σ s_j path with <= N_KF nodes,
// ignoring coverage) improved by local search on the full objective; that path is
// also the fallback (status greedy_fallback when the root LP does not finish in
// time). trim_time_limit_s bounds the whole call: model, root LP (Clp wall
// limit) and CBC. If no arc path with <= N_KF keyframes exists, the path with the
// fewest keyframes is returned (status infeasible_relaxed).
#pragma once

#include <vector>

#include "hermes/core/map_types.h"
#include "hermes/distill/landmark_selection.h"
#include "hermes/distill/params.h"

namespace hermes {
namespace distill {

/// s_j of every keyframe of the window (0 for a single keyframe).
std::vector<double> keyframeSeparation(const Submap& window, const DistillParams& params);

/// The window's motion in separation units: the sum over consecutive keyframes
/// of trim_w_rot x angle + trim_w_trans x distance.
double windowMotion(const Submap& window, const DistillParams& params);

/// Keyframes a window may keep from the budget's surplus for how fast its view
/// changes: the larger of ceil(windowMotion / motion_keyframe_spacing) and
/// ceil(tracked_keyframe_fraction x its keyframes), clamped to [max_keyframes,
/// trouble_max_keyframes]; a rule whose parameter is 0 is off.
int surplusKeyframeCap(const Submap& window, const DistillParams& params);

/// Number of landmarks keyframes a and b (indices) both observe.
int sharedLandmarks(const Submap& window, std::size_t a, std::size_t b);

struct TrimResult {
  SolveStatus status = SolveStatus::kOptimal;
  std::vector<int> kept;        ///< keyframe indices, ascending, first and last included
  double objective = 0;         ///< Σ s_j y_j − λ Σ ε_l
  double coverage_slack = 0;    ///< Σ ε_l
  double solve_time_s = 0;
};

TrimResult trimKeyframes(const Submap& window, int max_keyframes, const DistillParams& params);

/// Objective (Eq. 15) of a kept set, and its coverage slack.
double trimObjective(const Submap& window, const std::vector<int>& kept,
                     const DistillParams& params, double* coverage_slack = nullptr);

/// The window restricted to `kept` keyframes: observations by dropped keyframes
/// removed, landmarks that no kept keyframe observes dropped (and their keypoint
/// links cleared), odometry edges between consecutive kept keyframes: the
/// window's edges between them composed with their covariances (composeEdges),
/// so an edge across dropped keyframes is as uncertain as the odometry it
/// stands for; where the window has no edge chain between two kept keyframes
/// (windows merged after a deferral) none is sent and the server bridges them.
Submap applyKeyframeTrim(const Submap& window, const std::vector<int>& kept);

/// Keeps the landmarks with the given indices. Keyframes keep the keypoints
/// linked to kept landmarks and, each, up to `extra_keypoints` others (with a
/// measured depth first, spread over the keyframe; kAllKeypoints keeps every
/// one); observations are re-indexed.
inline constexpr std::size_t kAllKeypoints = static_cast<std::size_t>(-1);
Submap keepLandmarks(const Submap& submap, const std::vector<int>& landmark_indices,
                     std::size_t extra_keypoints);

/// What keepLandmarks(submap, landmark_indices, 0) leaves out: every keyframe
/// with only its keypoints not linked to a kept landmark (links cleared); no
/// landmarks, no odometry. Kept by the agent for later keyframe extensions.
Submap heldBackKeypoints(const Submap& submap, const std::vector<int>& landmark_indices);

/// Keyframe extensions (see Submap) of `held`'s keyframes: up to `n` of each
/// one's keypoints, chosen as keepLandmarks chooses its extras. Keyframes left
/// without a keypoint are omitted.
std::vector<Keyframe> keyframeExtensions(const Submap& held, std::size_t n);

}  // namespace distill
}  // namespace hermes
