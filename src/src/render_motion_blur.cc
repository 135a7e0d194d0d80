// Motion blur: per-pixel smear of one mid-exposure render along the image
// motion of its scene point during the exposure.
#include "hermes/core/render/motion_blur.h"

#include <algorithm>
#include <cmath>

namespace hermes {
namespace render {

ExposureMotion exposureMotion(const Trajectory& traj, const SE3& T_B_C, double t, double exposure_s) {
  auto at = [&](double tt) {
    SE3 T_W_B;
    interpolatePose(traj, std::clamp(tt, traj.front().t, traj.back().t), &T_W_B);
    return T_W_B * T_B_C;
  };
  const SE3 T_W_C = at(t);
  return {at(t - 0.5 * exposure_s).inverse() * T_W_C, at(t + 0.5 * exposure_s).inverse() * T_W_C};
}

namespace {

/// Bilinear sample of a CV_32F image at (x, y) in [0, cols - 1) x [0, rows - 1).
inline float bilinearInside(const cv::Mat& img, float x, float y) {
  const int x0 = static_cast<int>(x), y0 = static_cast<int>(y);
  const float a = x - x0, b = y - y0;
  const float* r0 = img.ptr<float>(y0) + x0;
  const float* r1 = img.ptr<float>(y0 + 1) + x0;
  return (1 - b) * (r0[0] + a * (r0[1] - r0[0])) + b * (r1[0] + a * (r1[1] - r1[0]));
}

/// Bilinear sample of a CV_32F image, coordinates clamped to the image.
inline float bilinear(const cv::Mat& img, float x, float y) {
  x = std::clamp(x, 0.0f, static_cast<float>(img.cols - 1));
  y = std::clamp(y, 0.0f, static_cast<float>(img.rows - 1));
  const int x0 = std::min(static_cast<int>(x), img.cols - 2), y0 = std::min(static_cast<int>(y), img.rows - 2);
  const float a = x - x0, b = y - y0;
  const float* r0 = img.ptr<float>(y0) + x0;
  const float* r1 = img.ptr<float>(y0 + 1) + x0;
  return (1 - b) * (r0[0] + a * (r0[1] - r0[0])) + b * (r1[0] + a * (r1[1] - r1[0]));
}

}  // namespace

BlurStats motionBlur(const cv::Mat& radiance, const cv::Mat& depth, const RayGrid& rays,
                     const PinholeIntrinsics& K, const ExposureMotion& m, int max_taps, cv::Mat* out) {
  CV_Assert(radiance.type() == CV_32F && depth.type() == CV_32F && radiance.size() == depth.size());
  CV_Assert(radiance.cols == rays.width() && radiance.rows == rays.height() && out != &radiance);
  CV_Assert(radiance.cols >= 2 && radiance.rows >= 2 && max_taps >= 2);
  out->create(radiance.size(), CV_32F);
  const Eigen::Matrix3f Rs = m.T_Cs_C.rotation().cast<float>(), Re = m.T_Ce_C.rotation().cast<float>();
  const Eigen::Vector3f ts = m.T_Cs_C.translation().cast<float>(), te = m.T_Ce_C.translation().cast<float>();
  const float fx = static_cast<float>(K.fx), fy = static_cast<float>(K.fy);
  double sum_len = 0, max_len = 0;
  for (int v = 0; v < radiance.rows; ++v) {
    const float* z = depth.ptr<float>(v);
    const float* src = radiance.ptr<float>(v);
    float* dst = out->ptr<float>(v);
    for (int u = 0; u < radiance.cols; ++u) {
      const float zz = (std::isfinite(z[u]) && z[u] > 0) ? z[u] : 1e4f;  // no depth: far away
      const Eigen::Vector3f X = zz * rays.ray(u, v);
      const Eigen::Vector3f Xs = Rs * X + ts, Xe = Re * X + te;
      if (Xs.z() <= 1e-3f || Xe.z() <= 1e-3f) {  // the point passes behind the camera
        dst[u] = src[u];
        continue;
      }
      // Normalised motion -> pixels through the ray grid's local Jacobian (the
      // lens distortion shrinks motion towards the border).
      const float nx = Xe.x() / Xe.z() - Xs.x() / Xs.z(), ny = Xe.y() / Xe.z() - Xs.y() / Xs.z();
      const Eigen::Vector4f& J = rays.pixelsPerNormalised(u, v);
      float du = J[0] * nx + J[1] * ny, dv = J[2] * nx + J[3] * ny;
      if (J.isZero()) du = fx * nx, dv = fy * ny;  // degenerate grid: pinhole
      const float len = std::sqrt(du * du + dv * dv);
      sum_len += len;
      max_len = std::max(max_len, static_cast<double>(len));
      if (len < 0.25f) {
        dst[u] = src[u];
        continue;
      }
      // Taps about one pixel apart, centred on the pixel (mid-exposure).
      const int n = std::min(max_taps, static_cast<int>(std::ceil(len)) + 1);
      const float hu = 0.5f * std::abs(du), hv = 0.5f * std::abs(dv);
      const bool inside = u - hu >= 0 && v - hv >= 0 && u + hu < radiance.cols - 1 && v + hv < radiance.rows - 1;
      float acc = 0;
      for (int k = 0; k < n; ++k) {
        const float tau = (k + 0.5f) / n - 0.5f;
        const float x = u + tau * du, y = v + tau * dv;
        acc += inside ? bilinearInside(radiance, x, y) : bilinear(radiance, x, y);
      }
      dst[u] = acc / n;
    }
  }
  return {sum_len / static_cast<double>(radiance.total()), max_len};
}

const cv::Mat& renderExposure(const Raycaster& rc, const PinholeIntrinsics& K, const Trajectory& traj,
                              const SE3& T_B_C, double t, const SensorParams& sensor, bool want_depth,
                              RenderOutput* ro, cv::Mat* blurred, BlurStats* stats) {
  SE3 T_W_B;
  interpolatePose(traj, std::clamp(t, traj.front().t, traj.back().t), &T_W_B);
  rc.render(T_W_B * T_B_C, ro, want_depth || sensor.motion_blur);
  if (!sensor.motion_blur) {
    if (stats) *stats = BlurStats{};
    return ro->radiance;
  }
  const BlurStats b = motionBlur(ro->radiance, ro->depth, rc.rays(), K,
                                 exposureMotion(traj, T_B_C, t, sensor.exposure_s), sensor.blur_max_taps, blurred);
  if (stats) *stats = b;
  return *blurred;
}

}  // namespace render
}  // namespace hermes
