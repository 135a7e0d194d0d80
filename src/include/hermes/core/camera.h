// Camera models: pinhole + radial-tangential (EuRoC), stereo rigs with
// rectification, pinhole RGB-D with a depth scale.
#pragma once

#include <array>
#include <string>

#include "hermes/core/geometry.h"
#include "hermes/core/map_types.h"
#include "hermes/core/status.h"

namespace hermes {

/// Pinhole camera with radial-tangential distortion (k1, k2, p1, p2), as in
/// EuRoC's sensor.yaml. Pixel coordinates: (0,0) is the centre of the top-left pixel.
struct PinholeRadtan {
  PinholeIntrinsics K;                    ///< intrinsics of the distorted image
  std::array<double, 4> dist{0, 0, 0, 0}; ///< k1, k2, p1, p2
  SE3 T_B_C;                              ///< body <- camera extrinsics (EuRoC T_BS)
  double rate_hz = 20.0;

  /// Distorts normalised image coordinates (x/z, y/z).
  Vec2 distort(const Vec2& xn) const;
  /// Inverse of distort() by Newton iteration (converges for EuRoC-like lenses).
  Vec2 undistortNormalized(const Vec2& xd) const;
  /// Projects a point in the camera frame to a distorted pixel; false if behind.
  bool project(const Vec3& p_C, Vec2* uv) const;
  /// Undistorts a pixel into the pixel frame of `out` (typically K itself).
  Vec2 undistortPixel(const Vec2& uv, const PinholeIntrinsics& out) const;
};

/// A pinhole depth camera (TUM / ICL-NUIM): depth_png_value / depth_scale = metres.
struct RgbdCamera {
  PinholeIntrinsics K;
  double depth_scale = 5000.0;  ///< TUM/ICL-NUIM: 5000 per metre
  SE3 T_B_C;
  double rate_hz = 30.0;
};

}  // namespace hermes
