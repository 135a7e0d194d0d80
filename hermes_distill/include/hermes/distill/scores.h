// Landmark scores of DESIGN §3: stability q_s (Def. 1) and the finite,
// future-aware information gain q_a (Th. 1), plus the α/β weighting rule.
//
// Frames. For an observation of landmark l in keyframe k, p is the unit bearing
// of the undistorted keypoint in camera k, and R̂·P_l is the landmark in camera k
// taken relative to the camera centre, i.e. P_C = R_C_A (P_A − t_A_C) (=T_C_A·P_A).
// Using P_C (not the raw agent-frame P_A) keeps W independent of where the agent
// frame's origin happens to be. W = [ [p]×[P_C]× , −[p]× ] (3×6; columns
// [rotation; translation]) is, up to sign, the Jacobian of the bearing residual
// p × P_C under a left perturbation of T_C_A, and Q = WᵀW.
//
// Motion attention. The latest VO motion (T_Cprev_Ccurr over dt) is extrapolated
// with constant velocity to `future_poses` poses evenly spread over
// (0, future_horizon_s]. A landmark in front of a predicted camera and projecting
// inside its image adds W_fᵀW_f with the predicted bearing p_f = P_Cf/|P_Cf|.
#pragma once

#include <vector>

#include "hermes/core/map_types.h"
#include "hermes/distill/params.h"

namespace hermes {
namespace distill {

/// How tracking went over the frames of a window (the agent's view of its own
/// weak spots): frames fed, frames lost, frames tracked with few inliers.
struct TrackingHealth {
  int frames = 0;
  int lost = 0;  ///< tracking failed
  int weak = 0;  ///< tracked, with fewer inliers than tracker.weak_tracked
  int min_tracked = 0;  ///< fewest inliers of a tracked frame (0: none tracked)
};

/// The latest visual-odometry motion of the camera, and the tracking health of
/// the window it comes with.
struct MotionHint {
  bool valid = false;
  SE3 T_A_C;          ///< latest camera pose (agent <- camera)
  SE3 T_Cprev_Ccurr;  ///< motion between the last two tracked frames
  double dt_s = 0.05; ///< time between those frames [s]
  std::uint32_t camera_id = 0;
  TrackingHealth health;  ///< over the window handed out with this hint (valid or not)
};

/// Constant-velocity extrapolation: `count` poses at (i/count)·horizon, i = 1..count.
std::vector<SE3> predictFuturePoses(const MotionHint& hint, int count, double horizon_s);

/// 3×6 W of one bearing p (unit, camera frame) of the point P_C (camera frame).
Eigen::Matrix<double, 3, 6> bearingJacobian(const Vec3& p, const Vec3& P_C);

/// log det of a symmetric positive definite 6×6 matrix (−inf if not SPD).
double logDetSpd(const Mat6& M);

/// q_a = log det(δI + Λ) − 6 log δ  (>= 0, 0 for Λ = 0).
double informationGain(const Mat6& Lambda, double delta);

/// f(S) = log det(δI + Σ_{l∈S} Λ_l) over the indices in `subset`.
double logDetObjective(const std::vector<Mat6>& lambdas, const std::vector<int>& subset,
                       double delta);

struct ScoreWeights {
  double alpha = 0.5, beta = 0.5;
};

/// α grows with loop closures, β with the mean rotation between consecutive
/// keyframes of the window; normalised so α + β = 1. With adaptive_weights off:
/// the configured α, β (normalised).
ScoreWeights scoreWeights(const Submap& window, int loop_closures, const DistillParams& params);

struct LandmarkScores {
  std::vector<double> q_s;     ///< per landmark of the submap (same order)
  std::vector<double> q_a;
  std::vector<double> value;   ///< v = α q̂_s + β q̂_a in [0, 1]
  std::vector<Mat6> lambda;    ///< Λ_l
  ScoreWeights weights;
};

/// Scores every landmark of `window` (observations by keyframes outside the
/// submap are ignored). Indices follow window.landmarks.
LandmarkScores computeScores(const Submap& window, const MotionHint& hint, int loop_closures,
                             const DistillParams& params);

/// Min-max normalisation to [0, 1] (all 1 when the values are equal).
std::vector<double> normalise01(const std::vector<double>& v);

}  // namespace distill
}  // namespace hermes
