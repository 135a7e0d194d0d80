// Trajectory alignment for evaluation: closed-form Umeyama (1991) least squares
// between matched point sets, rigid (SE(3)) or similarity (Sim(3)).
#pragma once

#include <string>
#include <vector>

#include "hermes/core/geometry.h"
#include "hermes/core/status.h"

namespace hermes {
namespace eval {

/// How an estimated trajectory is brought into the ground-truth frame.
enum class AlignMode {
  kNone,       ///< estimate already in the gt frame (T_gt_est = identity)
  kFirstPose,  ///< T_gt_est = G_0 * E_0^-1 (first matched pose pair)
  kSE3,        ///< rigid Umeyama over all matched positions
  kSim3,       ///< Umeyama with scale
};

const char* toString(AlignMode mode);  ///< "none" | "first" | "se3" | "sim3"
/// Parses the names of toString(); the error lists the valid ones.
Expected<AlignMode> parseAlignMode(const std::string& name);

/// p_gt ≈ scale * (T_gt_est.rotation() * p_est) + T_gt_est.translation().
struct Alignment {
  AlignMode mode = AlignMode::kNone;
  SE3 T_gt_est;
  double scale = 1.0;

  Vec3 applyToPoint(const Vec3& p_est) const {
    return scale * (T_gt_est.quat() * p_est) + T_gt_est.translation();
  }
  /// Pose of the estimate in the gt frame (translation scaled, rotation as is).
  SE3 applyToPose(const SE3& T_est_B) const {
    return SE3(T_gt_est.quat() * T_est_B.quat(), applyToPoint(T_est_B.translation()));
  }
};

/// Umeyama: minimises sum ||dst_i - (s R src_i + t)||^2 over R in SO(3), t and
/// (with_scale) s > 0. Needs >= 3 pairs of equal count and, with scale, source
/// points that are not all identical; errors say which condition failed.
Expected<Alignment> umeyama(const std::vector<Vec3>& src, const std::vector<Vec3>& dst,
                            bool with_scale);

/// Alignment of matched poses by mode: est_i -> gt_i. kFirstPose uses pair 0.
Expected<Alignment> alignPoses(const std::vector<SE3>& gt, const std::vector<SE3>& est,
                               AlignMode mode);

}  // namespace eval
}  // namespace hermes
