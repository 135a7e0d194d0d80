#include "frontend_synthetic.h"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace hermes::test {

std::string opencvSampleDir() { return "/usr/share/doc/opencv-doc/examples/data"; }

cv::Mat loadSampleGrey(const std::string& name) {
  return cv::imread(opencvSampleDir() + "/" + name, cv::IMREAD_GRAYSCALE);
}

SyntheticStereo makeFrontoParallelPair(const cv::Mat& texture, double depth, double baseline,
                                       double fx) {
  SyntheticStereo s;
  const int W = 752, H = 480;
  s.K.fx = s.K.fy = fx;
  s.K.cx = (W - 1) / 2.0;
  s.K.cy = (H - 1) / 2.0;
  s.K.width = W;
  s.K.height = H;
  s.baseline = baseline;
  s.depth = depth;
  s.disparity = fx * baseline / depth;
  // Scale the texture to cover the crop plus the disparity, band-limit it a
  // little (optics) so that bilinear resampling is close to the true shift.
  const double need_w = W + s.disparity + 20, need_h = H + 20;
  const double f = std::max({need_w / texture.cols, need_h / texture.rows, 1.0});
  cv::Mat big;
  cv::resize(texture, big, cv::Size(), f, f, cv::INTER_CUBIC);
  cv::GaussianBlur(big, big, cv::Size(0, 0), 0.8);
  const double ox = 10, oy = 10;
  // dst(x, y) = big(x + ox, y + oy): a point at left column x appears at x - d.
  cv::Mat ml = (cv::Mat_<double>(2, 3) << 1, 0, ox, 0, 1, oy);
  cv::Mat mr = (cv::Mat_<double>(2, 3) << 1, 0, ox + s.disparity, 0, 1, oy);
  cv::warpAffine(big, s.left, ml, cv::Size(W, H), cv::INTER_LINEAR | cv::WARP_INVERSE_MAP,
                 cv::BORDER_REFLECT);
  cv::warpAffine(big, s.right, mr, cv::Size(W, H), cv::INTER_LINEAR | cv::WARP_INVERSE_MAP,
                 cv::BORDER_REFLECT);
  return s;
}

}  // namespace hermes::test
