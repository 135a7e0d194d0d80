// Sensor model of the synthetic renderer: smooth exposure drift with occasional
// auto-exposure steps, vignetting, Gaussian read noise, 8-bit quantisation.
#pragma once

#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>

#include "hermes/core/config.h"
#include "hermes/core/status.h"

namespace hermes {
namespace render {

struct SensorParams {
  double noise_sigma = 2.0;       ///< Gaussian read noise [grey levels]
  double vignetting = 0.25;       ///< brightness loss at the image corner (0 = none)
  double drift_amplitude = 0.15;  ///< log-gain amplitude of the smooth drift
  double step_amplitude = 0.22;   ///< max |log-gain| of an exposure step
  double step_period_s = 9.0;     ///< one possible exposure step per period [s]
  double step_probability = 0.4;  ///< chance that a period holds a step
  bool noise = true;
  /// Reads keys under `prefix` (e.g. render.sensor.noise_sigma), then validates.
  Status read(const Config& c, const std::string& prefix = "render.sensor");
  Status validate() const;
};

/// Deterministic sensor; frames are identified by (time, camera index).
class Sensor {
 public:
  Sensor(const SensorParams& p, std::uint64_t seed, int width, int height);
  /// Exposure gain at time t [s] (same for all cameras of a rig).
  double gain(double t) const;
  /// Radiance (CV_32F) -> 8-bit image at time t for camera `cam`.
  cv::Mat expose(const cv::Mat& radiance, double t, int cam) const;

 private:
  double stepLevel(std::int64_t k) const;
  SensorParams p_;
  std::uint64_t seed_;
  cv::Mat vignette_;  ///< CV_32F multiplicative factor
  std::vector<float> noise_table_;  ///< 2^21 N(0,1) samples
};

/// SplitMix64 hash, used to derive independent seeds.
std::uint64_t mixSeed(std::uint64_t a, std::uint64_t b);

}  // namespace render
}  // namespace hermes
