#include "hermes/agent/rgbd_depth.h"

#include <cmath>

namespace hermes {

Status RgbdDepthParams::read(const Config& c, const std::string& p) {
  for (auto [key, ptr] : {std::pair<const char*, double*>{"min_depth", &min_depth},
                          {"max_depth", &max_depth},
                          {"max_relative_spread", &max_relative_spread}}) {
    Status s = c.get(p + "." + key, ptr);
    if (!s) return s;
  }
  Status s = c.get(p + ".neighbourhood", &neighbourhood);
  if (!s) return s;
  return validate();
}

void RgbdDepthParams::write(ConfigWriter* w, const std::string& p) const {
  w->set(p + ".min_depth", min_depth);
  w->set(p + ".max_depth", max_depth);
  w->set(p + ".neighbourhood", neighbourhood);
  w->set(p + ".max_relative_spread", max_relative_spread);
}

Status RgbdDepthParams::validate() const {
  if (!(min_depth > 0 && max_depth > min_depth))
    return Error{"rgbd.min_depth/max_depth must satisfy 0 < min_depth < max_depth"};
  if (neighbourhood < 0 || neighbourhood > 5) return Error{"rgbd.neighbourhood must be in [0, 5]"};
  if (!(max_relative_spread > 0)) return Error{"rgbd.max_relative_spread must be > 0"};
  return Status::Ok();
}

Expected<cv::Mat> depthToMetres(const cv::Mat& raw, double scale) {
  if (raw.empty()) return Error{"depth image is empty"};
  cv::Mat out;
  if (raw.type() == CV_16UC1) {
    if (!(scale > 0)) return Error{"depth scale must be > 0"};
    raw.convertTo(out, CV_32F, 1.0 / scale);
  } else if (raw.type() == CV_32FC1) {
    out = raw.clone();
    for (int y = 0; y < out.rows; ++y) {
      float* r = out.ptr<float>(y);
      for (int x = 0; x < out.cols; ++x)
        if (!std::isfinite(r[x]) || r[x] < 0) r[x] = 0.f;
    }
  } else {
    return Error{"depth image type " + std::to_string(raw.type()) +
                 " is neither CV_16UC1 nor CV_32FC1"};
  }
  return out;
}

Expected<int> assignDepthFromImage(const cv::Mat& depth, const RgbdDepthParams& p,
                                   FeatureSet* fs) {
  if (depth.type() != CV_32FC1)
    return Error{"keypoint depth: depth image must be CV_32FC1 metres, got type " +
                 std::to_string(depth.type())};
  if (depth.cols != fs->width || depth.rows != fs->height)
    return Error{"keypoint depth: depth image " + std::to_string(depth.cols) + "x" +
                 std::to_string(depth.rows) + " does not match the grey image " +
                 std::to_string(fs->width) + "x" + std::to_string(fs->height)};
  const int w = p.neighbourhood;
  int count = 0;
  for (auto& k : fs->keypoints) {
    k.depth = 0.f;
    const int x = int(std::lround(k.u)), y = int(std::lround(k.v));
    if (x - w < 0 || y - w < 0 || x + w >= depth.cols || y + w >= depth.rows) continue;
    const float z = depth.at<float>(y, x);
    if (!std::isfinite(z) || z < p.min_depth || z > p.max_depth) continue;
    bool consistent = true;
    for (int dy = -w; dy <= w && consistent; ++dy)
      for (int dx = -w; dx <= w; ++dx) {
        const float zn = depth.at<float>(y + dy, x + dx);
        if (!std::isfinite(zn) || std::abs(zn - z) > p.max_relative_spread * z) {
          consistent = false;
          break;
        }
      }
    if (!consistent) continue;
    k.depth = z;
    ++count;
  }
  return count;
}

}  // namespace hermes
