// Keypoint depth from a registered metric depth image (RGB-D cameras).
#pragma once

#include <string>

#include <opencv2/core.hpp>

#include "hermes/agent/orb_extractor.h"
#include "hermes/core/config.h"
#include "hermes/core/status.h"

namespace hermes {

struct RgbdDepthParams {
  double min_depth = 0.1;            ///< nearest valid depth [m]
  double max_depth = 8.0;            ///< farthest valid depth [m]
  int neighbourhood = 1;             ///< half size of the consistency window [px]
  double max_relative_spread = 0.05; ///< reject if a window depth differs by more (depth edge)

  Status read(const Config& config, const std::string& prefix = "rgbd");
  void write(ConfigWriter* writer, const std::string& prefix = "rgbd") const;
  Status validate() const;
};

/// Converts a raw depth image (CV_16U, value / scale = metres; 0 = no data) or an
/// already metric CV_32F image into CV_32F metres (invalid -> 0).
Expected<cv::Mat> depthToMetres(const cv::Mat& raw, double scale);

/// Writes keypoints[i].depth from `depth_m` (CV_32F metres, same size as the
/// image the features come from). A depth is kept only if finite, inside
/// [min_depth, max_depth] and consistent over the window around the keypoint
/// (no depth discontinuity, no hole); otherwise it is set to 0. Returns the
/// number of keypoints with depth; errors name a wrong type or size.
Expected<int> assignDepthFromImage(const cv::Mat& depth_m, const RgbdDepthParams& params,
                                   FeatureSet* features);

}  // namespace hermes
