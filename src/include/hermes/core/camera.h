// Camera models: pinhole + radial-tangential (EuRoC, ROS plumb_bob /
// rational_polynomial) or equidistant (Kannala-Brandt, OpenCV fisheye) lens
// distortion; pinhole RGB-D with a depth scale. Stereo rigs: stereo_rig.h.
#pragma once

#include <array>
#include <string>

#include "hermes/core/geometry.h"
#include "hermes/core/map_types.h"
#include "hermes/core/status.h"

namespace hermes {

/// Lens distortion of a PinholeRadtan.
enum class DistortionModel {
  /// Radial-tangential (OpenCV order): k1 k2 p1 p2 [k3 [k4 k5 k6]]. EuRoC and
  /// Kalibr "radtan" use the first four, ROS plumb_bob five, rational_polynomial
  /// eight; unused coefficients are 0 (all zero = no distortion).
  kRadtan,
  /// Equidistant / Kannala-Brandt (Kalibr "equidistant", ROS "equidistant",
  /// cv::fisheye): theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 +
  /// k4 theta^8) with theta the angle to the optical axis; dist = k1 k2 k3 k4.
  kEquidistant,
};
const char* toString(DistortionModel m);

/// Pinhole camera with lens distortion (radial-tangential by default, as in
/// EuRoC's sensor.yaml; the name predates the equidistant model). Pixel
/// coordinates: (0,0) is the centre of the top-left pixel.
struct PinholeRadtan {
  PinholeIntrinsics K;  ///< intrinsics of the distorted image
  DistortionModel model = DistortionModel::kRadtan;
  std::array<double, 8> dist{};  ///< coefficients of `model` (see DistortionModel)
  SE3 T_B_C;                     ///< body <- camera extrinsics (EuRoC T_BS)
  double rate_hz = 20.0;         ///< [Hz]; 0 when the calibration file gives none

  /// Number of meaningful coefficients: 4 (radtan with k3..k6 zero, and
  /// equidistant), 5 (k3 set, k4..k6 zero) or 8.
  int distortionCount() const;
  bool hasDistortion() const;

  /// Distorts normalised image coordinates (x/z, y/z).
  Vec2 distort(const Vec2& xn) const;
  /// Inverse of distort(): Newton iteration (radtan, converges for EuRoC-like
  /// lenses) or a 1-D Newton solve for the angle theta (equidistant, for
  /// theta < 90 deg).
  Vec2 undistortNormalized(const Vec2& xd) const;
  /// Projects a point in the camera frame to a distorted pixel; false if behind.
  bool project(const Vec3& p_C, Vec2* uv) const;
  /// Undistorts a pixel into the pixel frame of `out` (typically K itself).
  Vec2 undistortPixel(const Vec2& uv, const PinholeIntrinsics& out) const;
};

/// A pinhole depth camera (TUM / ICL-NUIM): depth_png_value / depth_scale = metres.
/// K and `dist` describe the colour image; the depth image is registered to it.
struct RgbdCamera {
  PinholeIntrinsics K;
  /// Colour lens distortion, ROS plumb_bob order k1 k2 p1 p2 k3 (TUM fr1/fr2
  /// publish one; all zero = undistorted images, e.g. TUM fr3, ICL-NUIM).
  std::array<double, 5> dist{};
  double depth_scale = 5000.0;  ///< TUM/ICL-NUIM: 5000 per metre
  SE3 T_B_C;
  double rate_hz = 30.0;

  bool hasDistortion() const;
  /// The colour camera as a PinholeRadtan (radtan, same K, dist, T_B_C, rate),
  /// e.g. for undistorting keypoints with PinholeRadtan::undistortPixel().
  PinholeRadtan colourCamera() const;
};

}  // namespace hermes
