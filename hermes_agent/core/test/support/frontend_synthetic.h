// Test fixtures for the visual front end: real textures from opencv-doc and
// exactly known synthetic stereo pairs made by warping them.
#pragma once

#include <string>

#include <opencv2/core.hpp>

#include "hermes/core/map_types.h"

namespace hermes::test {

/// Directory of the opencv-doc sample images.
std::string opencvSampleDir();

/// Loads an opencv-doc sample image as 8-bit grey; empty Mat if missing.
cv::Mat loadSampleGrey(const std::string& name);

/// A rectified stereo pair seeing a fronto-parallel textured plane.
struct SyntheticStereo {
  cv::Mat left, right;
  PinholeIntrinsics K;
  double baseline = 0;   ///< [m]
  double depth = 0;      ///< plane depth [m]
  double disparity = 0;  ///< exact disparity fx * b / depth [px]
};

/// Makes a 752x480 pair from `texture`: left is a crop, right is the same crop
/// shifted by the exact (non-integer) disparity with bilinear interpolation.
SyntheticStereo makeFrontoParallelPair(const cv::Mat& texture, double depth, double baseline,
                                       double fx);

}  // namespace hermes::test
