#include "plane_scene.h"

#include <limits>

#include <opencv2/imgproc.hpp>

#include "frontend_synthetic.h"

namespace hermes::test {

cv::Mat renderPlanes(const std::vector<TexturedPlane>& planes, const PinholeIntrinsics& K,
                     const SE3& T_W_C, cv::Mat* depth) {
  const int W = K.width, H = K.height;
  const Mat3 R = T_W_C.rotation();
  const Vec3 o = T_W_C.translation();
  std::vector<cv::Mat> mapx(planes.size()), mapy(planes.size());
  for (auto& m : mapx) m.create(H, W, CV_32F), m.setTo(-1.f);
  for (auto& m : mapy) m.create(H, W, CV_32F), m.setTo(-1.f);
  cv::Mat label(H, W, CV_32S, cv::Scalar(-1));
  cv::Mat z(H, W, CV_32F, cv::Scalar(0.f));
  std::vector<Vec3> normal(planes.size());
  for (std::size_t p = 0; p < planes.size(); ++p) normal[p] = planes[p].e1.cross(planes[p].e2);
  for (int v = 0; v < H; ++v)
    for (int u = 0; u < W; ++u) {
      const Vec3 d = R * Vec3((u - K.cx) / K.fx, (v - K.cy) / K.fy, 1.0);  // z_C = 1
      double best = std::numeric_limits<double>::infinity();
      for (std::size_t p = 0; p < planes.size(); ++p) {
        const TexturedPlane& pl = planes[p];
        const double den = normal[p].dot(d);
        if (std::abs(den) < 1e-12) continue;
        const double s = normal[p].dot(pl.origin - o) / den;
        if (s <= 1e-6 || s >= best) continue;
        const Vec3 q = o + s * d - pl.origin;
        const double a = q.dot(pl.e1), b = q.dot(pl.e2);
        if (a < 0 || b < 0 || a > pl.width || b > pl.height) continue;
        best = s;
        label.at<int>(v, u) = int(p);
        mapx[p].at<float>(v, u) = float(a / pl.width * (pl.texture.cols - 1));
        mapy[p].at<float>(v, u) = float(b / pl.height * (pl.texture.rows - 1));
      }
      if (std::isfinite(best)) z.at<float>(v, u) = float(best);
    }
  cv::Mat out(H, W, CV_8UC1, cv::Scalar(0));
  for (std::size_t p = 0; p < planes.size(); ++p) {
    cv::Mat img;
    cv::remap(planes[p].texture, img, mapx[p], mapy[p], cv::INTER_LINEAR, cv::BORDER_REPLICATE);
    img.copyTo(out, label == int(p));
  }
  if (depth) *depth = z;
  return out;
}

std::vector<TexturedPlane> roomCornerScene() {
  const cv::Mat a = loadSampleGrey("building.jpg"), b = loadSampleGrey("graf1.png"),
                c = loadSampleGrey("leuvenA.jpg");
  if (a.empty() || b.empty() || c.empty()) return {};
  std::vector<TexturedPlane> s(3);
  s[0] = {Vec3(-3, -2, 4), Vec3(1, 0, 0), Vec3(0, 1, 0), 6.0, 4.0, a};      // back wall
  s[1] = {Vec3(-3, 1.2, 0.3), Vec3(1, 0, 0), Vec3(0, 0, 1), 6.0, 3.7, b};   // floor
  s[2] = {Vec3(-2, -2, 0.3), Vec3(0, 0, 1), Vec3(0, 1, 0), 3.7, 3.2, c};    // left wall
  return s;
}

}  // namespace hermes::test
