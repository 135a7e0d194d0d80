// Calibrated stereo rig (two pinhole cameras with radtan or equidistant lens
// distortion, both the same model) and its rectification: a shared pinhole K,
// horizontal epipolar lines, zero disparity at infinity. Frames: Cl/Cr
// original cameras, Crect the rectified left camera.
#pragma once

#include <opencv2/core.hpp>

#include "hermes/core/camera.h"
#include "hermes/core/geometry.h"
#include "hermes/core/status.h"

namespace hermes {

struct StereoRig {
  PinholeRadtan left, right;  ///< each with its own T_B_C (body <- camera)

  /// Right camera pose in the left camera frame: T_Cl_Cr = T_B_Cl^-1 * T_B_Cr.
  SE3 T_Cl_Cr() const { return left.T_B_C.inverse() * right.T_B_C; }
};

/// Options of rectify().
struct RectifyOptions {
  /// OpenCV's free scaling: 0 keeps only valid pixels (no black borders),
  /// 1 keeps every source pixel.
  double alpha = 0.0;
  /// Fixed-point remap tables (CV_16SC2 + CV_16UC1: faster remap, 1/32 px
  /// interpolation) instead of float tables.
  bool fixed_point_maps = true;
};

/// Result of rectify(): geometry plus remap tables.
class RectifiedStereo {
 public:
  PinholeIntrinsics K;  ///< shared by both rectified images
  double baseline = 0;  ///< [m]; rectified right = rectified left shifted by +baseline in x
  Mat3 R_rect_left = Mat3::Identity();   ///< rectified-left <- original-left camera
  Mat3 R_rect_right = Mat3::Identity();  ///< rectified-right <- original-right camera
  SE3 T_B_Crect;  ///< body <- rectified left camera (map trajectories through this)
  StereoRig rig;  ///< the original cameras
  cv::Mat map_left_x, map_left_y, map_right_x, map_right_y;  ///< remap tables

  /// Remaps raw images (rig resolution) into the rectified frame. Output
  /// pointers may not alias inputs.
  void rectifyImages(const cv::Mat& l, const cv::Mat& r, cv::Mat* lr, cv::Mat* rr) const;

  /// Maps a distorted pixel of the original left (right) image to the
  /// rectified left (right) image.
  Vec2 rectifyPointLeft(const Vec2& distorted_px) const;
  Vec2 rectifyPointRight(const Vec2& distorted_px) const;

  /// Disparity [px] of a point at depth z [m] in the rectified frame: fx*b/z.
  double disparityAtDepth(double z) const { return K.fx * baseline / z; }
  /// Depth [m] from disparity [px]; 0 when the disparity is not positive.
  double depthFromDisparity(double d) const { return d > 0 ? K.fx * baseline / d : 0.0; }
};

/// Builds the rectification with cv::stereoRectify (CALIB_ZERO_DISPARITY) and
/// cv::initUndistortRectifyMap; for equidistant cameras with cv::fisheye's
/// versions (opt.alpha is then fisheye's "balance"). Errors when the rig is
/// degenerate (different resolutions or distortion models, zero baseline,
/// non-horizontal arrangement).
Expected<RectifiedStereo> rectify(const StereoRig& rig, const RectifyOptions& opt = {});

}  // namespace hermes
