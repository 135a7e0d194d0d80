#include "hermes/core/stereo_rig.h"

#include <cmath>
#include <string>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

namespace hermes {
namespace {

cv::Mat cameraMatrix(const PinholeIntrinsics& K) {
  return (cv::Mat_<double>(3, 3) << K.fx, 0, K.cx, 0, K.fy, K.cy, 0, 0, 1);
}

// 4, 5 or 8 coefficients in OpenCV's order (cv::fisheye takes exactly 4).
cv::Mat distCoeffs(const PinholeRadtan& c) {
  const int n = c.distortionCount();
  cv::Mat d(1, n, CV_64F);
  for (int i = 0; i < n; ++i) d.at<double>(0, i) = c.dist[i];
  return d;
}

Mat3 toEigen3(const cv::Mat& m) {
  Mat3 R;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) R(r, c) = m.at<double>(r, c);
  return R;
}

Vec2 rectifyPoint(const PinholeRadtan& cam, const Mat3& R_rect, const PinholeIntrinsics& K,
                  const Vec2& uv) {
  const Vec2 xd((uv.x() - cam.K.cx) / cam.K.fx, (uv.y() - cam.K.cy) / cam.K.fy);
  const Vec2 xn = cam.undistortNormalized(xd);
  const Vec3 ray = R_rect * Vec3(xn.x(), xn.y(), 1.0);
  return Vec2(K.fx * ray.x() / ray.z() + K.cx, K.fy * ray.y() / ray.z() + K.cy);
}

}  // namespace

Expected<RectifiedStereo> rectify(const StereoRig& rig, const RectifyOptions& opt) {
  const PinholeIntrinsics& Kl = rig.left.K;
  const PinholeIntrinsics& Kr = rig.right.K;
  if (Kl.width != Kr.width || Kl.height != Kr.height || Kl.width <= 0 || Kl.height <= 0)
    return Error{"stereo rig: left and right resolutions differ or are empty (" +
                 std::to_string(Kl.width) + "x" + std::to_string(Kl.height) + " vs " +
                 std::to_string(Kr.width) + "x" + std::to_string(Kr.height) + ")"};
  if (!(opt.alpha >= 0.0 && opt.alpha <= 1.0))
    return Error{"rectify: alpha must lie in [0, 1]"};
  const bool fisheye = rig.left.model == DistortionModel::kEquidistant;
  if (rig.left.model != rig.right.model)
    return Error{std::string("stereo rig: left and right distortion models differ (") +
                 toString(rig.left.model) + " vs " + toString(rig.right.model) + ")"};

  // OpenCV wants R, T with x_right = R x_left + T, i.e. T_Cr_Cl.
  const SE3 T_Cr_Cl = rig.T_Cl_Cr().inverse();
  const Vec3 t = T_Cr_Cl.translation();
  if (t.norm() < 1e-6) return Error{"stereo rig: baseline is zero"};
  if (std::abs(t.x()) < std::abs(t.y()))
    return Error{"stereo rig: cameras are arranged vertically; only horizontal rigs are supported"};
  const Mat3 Rcv = T_Cr_Cl.rotation();
  cv::Mat R(3, 3, CV_64F), T(3, 1, CV_64F);
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) R.at<double>(r, c) = Rcv(r, c);
    T.at<double>(r) = t(r);
  }
  const cv::Size size(Kl.width, Kl.height);
  cv::Mat R1, R2, P1, P2, Q;
  if (fisheye)  // alpha becomes cv::fisheye's "balance" (0: valid pixels, 1: all pixels)
    cv::fisheye::stereoRectify(cameraMatrix(Kl), distCoeffs(rig.left), cameraMatrix(Kr),
                               distCoeffs(rig.right), size, R, T, R1, R2, P1, P2, Q,
                               cv::CALIB_ZERO_DISPARITY, size, opt.alpha);
  else
    cv::stereoRectify(cameraMatrix(Kl), distCoeffs(rig.left), cameraMatrix(Kr),
                      distCoeffs(rig.right), size, R, T, R1, R2, P1, P2, Q,
                      cv::CALIB_ZERO_DISPARITY, opt.alpha, size);

  RectifiedStereo out;
  out.rig = rig;
  out.K.fx = P1.at<double>(0, 0);
  out.K.fy = P1.at<double>(1, 1);
  out.K.cx = P1.at<double>(0, 2);
  out.K.cy = P1.at<double>(1, 2);
  out.K.width = size.width;
  out.K.height = size.height;
  // P2 = K [I | (-f b, 0, 0)]: the rectified right camera sits at +b along x.
  out.baseline = -P2.at<double>(0, 3) / P2.at<double>(0, 0);
  if (!(out.baseline > 0) || !std::isfinite(out.baseline) || !(out.K.fx > 0))
    return Error{"stereo rig: rectification failed (left camera must be on the left)"};
  // cv::fisheye estimates the new camera from the image border; lenses seeing
  // 90 deg or more off axis there give a meaningless principal point.
  if (fisheye && !(out.K.cx >= 0 && out.K.cx <= size.width && out.K.cy >= 0 &&
                   out.K.cy <= size.height))
    return Error{"stereo rig: fisheye rectification failed (principal point outside the "
                 "image: field of view too wide for one pinhole image)"};
  out.R_rect_left = toEigen3(R1);
  out.R_rect_right = toEigen3(R2);
  // p_rect = R1 p_Cl  =>  T_Cl_Crect has rotation R1^T and no translation.
  out.T_B_Crect = rig.left.T_B_C * SE3(Mat3(out.R_rect_left.transpose()), Vec3::Zero());

  const int type = opt.fixed_point_maps ? CV_16SC2 : CV_32FC1;
  auto map = [&](const PinholeRadtan& cam, const cv::Mat& Rr, const cv::Mat& P, cv::Mat* mx,
                 cv::Mat* my) {
    if (fisheye)
      cv::fisheye::initUndistortRectifyMap(cameraMatrix(cam.K), distCoeffs(cam), Rr, P, size,
                                           type, *mx, *my);
    else
      cv::initUndistortRectifyMap(cameraMatrix(cam.K), distCoeffs(cam), Rr, P, size, type, *mx,
                                  *my);
  };
  map(rig.left, R1, P1, &out.map_left_x, &out.map_left_y);
  map(rig.right, R2, P2, &out.map_right_x, &out.map_right_y);
  return out;
}

void RectifiedStereo::rectifyImages(const cv::Mat& l, const cv::Mat& r, cv::Mat* lr,
                                    cv::Mat* rr) const {
  HERMES_CHECK(lr && rr && lr != rr, "rectifyImages needs two distinct outputs");
  HERMES_CHECK(l.cols == rig.left.K.width && l.rows == rig.left.K.height &&
                   r.cols == rig.right.K.width && r.rows == rig.right.K.height,
               "rectifyImages: image size differs from the calibration");
  cv::remap(l, *lr, map_left_x, map_left_y, cv::INTER_LINEAR, cv::BORDER_CONSTANT);
  cv::remap(r, *rr, map_right_x, map_right_y, cv::INTER_LINEAR, cv::BORDER_CONSTANT);
}

Vec2 RectifiedStereo::rectifyPointLeft(const Vec2& distorted_px) const {
  return rectifyPoint(rig.left, R_rect_left, K, distorted_px);
}

Vec2 RectifiedStereo::rectifyPointRight(const Vec2& distorted_px) const {
  return rectifyPoint(rig.right, R_rect_right, K, distorted_px);
}

}  // namespace hermes
