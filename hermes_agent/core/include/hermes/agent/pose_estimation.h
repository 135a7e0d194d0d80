// Camera pose from 2D-3D correspondences: PnP RANSAC (OpenCV's P3P minimal
// solver inside RANSAC) for an initial guess, then robust motion-only
// refinement: Levenberg-Marquardt on SE(3) with analytic Jacobians (6 unknowns,
// so no general solver is needed; the test checks it against a Ceres solve of
// the same cost), Huber loss on the reprojection error, observations whose
// error exceeds a chi-square bound are dropped between rounds. A keypoint with a
// stereo (or RGB-D) depth also constrains the right image's column, as in local
// BA: that pins the translation where the left image alone leaves a valley
// (distant points seen in a narrow view trade translation for rotation).
#pragma once

#include <string>
#include <vector>

#include <ceres/ceres.h>

#include "hermes/core/config.h"
#include "hermes/core/geometry.h"
#include "hermes/core/map_types.h"
#include "hermes/core/status.h"

namespace hermes {

struct PoseEstimationParams {
  double ransac_threshold_px = 2.5;  ///< RANSAC inlier reprojection error [px]
  int ransac_iterations = 300;
  double ransac_confidence = 0.999;
  double huber_px = 2.45;            ///< Huber width on sigma-normalised error (sqrt(5.991))
  double chi2_threshold = 5.991;     ///< 95 % for 2 DoF, on sigma-normalised squared error
  double chi2_threshold_stereo = 7.815;  ///< 95 % for 3 DoF (observations with a right column)
  bool stereo_residual = true;       ///< use Correspondences::u_right where given
  /// The right column's sigma = this x the left one's. Its error is the left
  /// one's plus the disparity's; at 1 the whole-sequence odometry on the MH
  /// renders got worse (MH_04 4.87 -> 8.67 cm, demo 0.77 -> 1.00), at 2 it kept
  /// most of the gain on V1 without that loss (README, "stereo pose residual").
  double stereo_sigma_scale = 2.0;
  int refine_rounds = 4;             ///< optimise, reclassify outliers, repeat
  int iterations_per_round = 10;
  int min_inliers = 12;

  Status read(const Config& config, const std::string& prefix = "pose");
  void write(ConfigWriter* writer, const std::string& prefix = "pose") const;
  Status validate() const;
};

/// 2D-3D correspondences: point in the map frame W, undistorted pixel, and the
/// pixel standard deviation (e.g. scale^octave).
struct Correspondences {
  std::vector<Vec3> p_W;
  std::vector<Vec2> uv;
  std::vector<double> sigma_px;  ///< empty = 1 px for all
  /// Right-image column of each observation (u - fx * baseline / depth), < 0 =
  /// none; empty = none for all. Needs baseline > 0.
  std::vector<double> u_right;
  double baseline = 0;           ///< stereo baseline [m] (RGB-D: a virtual one)
  std::size_t size() const { return p_W.size(); }
};

struct PoseEstimate {
  SE3 T_C_W;                 ///< camera <- map
  std::vector<bool> inlier;  ///< per correspondence
  int num_inliers = 0;
  double rms_px = 0;         ///< RMS reprojection error of the inliers [px]
};

/// Reprojection residual of one observation, (u, v) residual divided by sigma.
/// Parameters: q_C_W as Eigen quaternion coefficients (x, y, z, w), t_C_W.
struct ReprojectionResidual {
  ReprojectionResidual(const Vec2& uv, const Vec3& p_W, const PinholeIntrinsics& K,
                       double sigma)
      : uv_(uv), p_W_(p_W), fx_(K.fx), fy_(K.fy), cx_(K.cx), cy_(K.cy), inv_sigma_(1.0 / sigma) {}

  template <class T>
  bool operator()(const T* q, const T* t, T* r) const {
    const Eigen::Quaternion<T> q_C_W(q[3], q[0], q[1], q[2]);
    const Eigen::Matrix<T, 3, 1> p_C =
        q_C_W * p_W_.cast<T>() + Eigen::Matrix<T, 3, 1>(t[0], t[1], t[2]);
    if (p_C.z() <= T(1e-6)) {  // behind the camera: a large constant residual
      r[0] = T(1e3);
      r[1] = T(1e3);
      return true;
    }
    r[0] = (T(fx_) * p_C.x() / p_C.z() + T(cx_) - T(uv_.x())) * T(inv_sigma_);
    r[1] = (T(fy_) * p_C.y() / p_C.z() + T(cy_) - T(uv_.y())) * T(inv_sigma_);
    return true;
  }

  static ceres::CostFunction* create(const Vec2& uv, const Vec3& p_W, const PinholeIntrinsics& K,
                                     double sigma) {
    return new ceres::AutoDiffCostFunction<ReprojectionResidual, 2, 4, 3>(
        new ReprojectionResidual(uv, p_W, K, sigma));
  }

 private:
  Vec2 uv_;
  Vec3 p_W_;
  double fx_, fy_, cx_, cy_, inv_sigma_;
};

/// PnP RANSAC (P3P) then refinePose(). Errors: too few correspondences or inliers.
Expected<PoseEstimate> estimatePose(const Correspondences& c, const PinholeIntrinsics& K,
                                    const PoseEstimationParams& params);

/// Robust motion-only refinement from an initial guess (e.g. the constant-velocity
/// prediction). `initial_inliers` (optional) restricts the first round.
/// `trusted` (optional): only these observations enter the optimisation; the
/// others are still classified against the result (inlier or not) but cannot
/// move the pose. Errors: fewer than min_inliers survive.
Expected<PoseEstimate> refinePose(const Correspondences& c, const PinholeIntrinsics& K,
                                  const SE3& T_C_W_init, const PoseEstimationParams& params,
                                  const std::vector<bool>* initial_inliers = nullptr,
                                  const std::vector<bool>* trusted = nullptr);

/// Mean pixel distance between the projections of c's points under two poses
/// (points in front of both cameras only; 0 if none).
double projectionShift(const Correspondences& c, const PinholeIntrinsics& K, const SE3& T_C_W_a,
                       const SE3& T_C_W_b);

}  // namespace hermes
