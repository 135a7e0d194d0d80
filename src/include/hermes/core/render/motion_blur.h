// Motion blur of the synthetic renderer: the sensor integrates the scene over
// its exposure while the camera moves. One render at mid-exposure (radiance +
// z-depth) is smeared, per pixel, along the straight image path that pixel's
// scene point travels between the start and the end of the exposure (a cheap
// stand-in for averaging sub-exposure renders; exact for a static scene away
// from occlusion boundaries, to first order in the motion).
#pragma once

#include <opencv2/core.hpp>

#include "hermes/core/camera.h"
#include "hermes/core/geometry.h"
#include "hermes/core/render/raycaster.h"
#include "hermes/core/render/sensor.h"
#include "hermes/core/trajectory.h"

namespace hermes {
namespace render {

/// Camera motion during one exposure: the mid-exposure camera frame C seen from
/// the frames at the start (Cs) and the end (Ce) of the exposure.
struct ExposureMotion {
  SE3 T_Cs_C, T_Ce_C;
};

/// Exposure motion of a camera (extrinsics T_B_C) on a body trajectory around
/// time t [s]; the exposure window is clamped to the trajectory's time range.
ExposureMotion exposureMotion(const Trajectory& traj_W_B, const SE3& T_B_C, double t, double exposure_s);

struct BlurStats {
  double mean_px = 0;  ///< mean length of the per-pixel smear [px]
  double max_px = 0;   ///< longest smear [px]
};

/// Smears `radiance` (CV_32F) along each pixel's motion; `depth` is the z-depth
/// (CV_32F) of the same render, `rays` its ray grid: normalised motion becomes
/// pixels through the grid's local Jacobian (so the lens distortion counts);
/// `K`'s focal lengths serve only where that Jacobian is degenerate. At most `max_taps` samples per pixel;
/// pixels that move less than a quarter pixel are copied. `out` may not alias.
BlurStats motionBlur(const cv::Mat& radiance, const cv::Mat& depth, const RayGrid& rays,
                     const PinholeIntrinsics& K, const ExposureMotion& motion, int max_taps, cv::Mat* out);

/// Renders the camera (extrinsics T_B_C, intrinsics K of rc's rays) on the body
/// trajectory at time t [s] (clamped to it) and returns the radiance to expose:
/// smeared over the exposure when sensor.motion_blur, else ro->radiance.
/// Depth is filled when want_depth (always with blur). `stats` may be null.
const cv::Mat& renderExposure(const Raycaster& rc, const PinholeIntrinsics& K, const Trajectory& traj_W_B,
                              const SE3& T_B_C, double t, const SensorParams& sensor, bool want_depth,
                              RenderOutput* ro, cv::Mat* blurred, BlurStats* stats = nullptr);

}  // namespace render
}  // namespace hermes
