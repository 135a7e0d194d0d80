// Plain frame types handed from the dataset readers to the runner / tracker.
#pragma once

#include <cstdint>

#include <opencv2/core.hpp>

namespace hermes {

/// One stereo pair. Images are 8-bit grey; rectified when `rectified` is true
/// (then they live in the pixel frame of RectifiedStereo::K).
struct StereoFrame {
  std::int64_t stamp_ns = 0;  ///< sensor stamp [ns] (exact, as in the dataset)
  double t = 0;               ///< the same stamp in seconds
  cv::Mat left, right;        ///< CV_8UC1
  bool rectified = false;
};

/// One associated RGB-D frame.
struct RgbdFrame {
  std::int64_t stamp_ns = 0;  ///< rgb stamp [ns] (rounded from the file's seconds)
  double t = 0;               ///< rgb stamp [s]
  double depth_t = 0;         ///< stamp of the associated depth image [s]
  cv::Mat rgb;                ///< CV_8UC3, BGR as loaded by OpenCV
  cv::Mat gray;               ///< CV_8UC1
  cv::Mat depth_m;            ///< CV_32FC1 metres, 0 = no measurement
};

/// Seconds from an integer nanosecond stamp without losing more than the
/// final rounding (the integer seconds and the fraction are converted apart).
inline double nsToSeconds(std::int64_t ns) {
  const std::int64_t s = ns / 1000000000;
  const std::int64_t rem = ns % 1000000000;
  return static_cast<double>(s) + static_cast<double>(rem) * 1e-9;
}

}  // namespace hermes
