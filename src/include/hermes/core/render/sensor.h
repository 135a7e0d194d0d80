// Sensor model of the synthetic renderer: smooth exposure drift with occasional
// auto-exposure steps, vignetting, Gaussian read noise (optionally plus
// signal-dependent photon noise), 8-bit quantisation, and the exposure time
// over which the renderer smears the image when motion blur is on.
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
  double brightness = 1.0;        ///< constant exposure gain on top of the drift
  double vignetting = 0.25;       ///< brightness loss at the image corner (0 = none)
  double drift_amplitude = 0.15;  ///< log-gain amplitude of the smooth drift
  double step_amplitude = 0.22;   ///< max |log-gain| of an exposure step
  double step_period_s = 9.0;     ///< one possible exposure step per period [s]
  double step_probability = 0.4;  ///< chance that a period holds a step
  bool noise = true;
  /// Photon (shot) noise: variance grows with the signal, sigma^2(I) =
  /// noise_sigma^2 + photon_gain * I (I = expected grey level). Off: read noise only.
  bool photon_noise = false;
  double photon_gain = 0.06;      ///< [grey levels^2 per grey level]
  /// Motion blur: the image integrates the scene over exposure_s around the
  /// frame time (the renderer smears along each pixel's motion).
  bool motion_blur = false;
  double exposure_s = 0.005;      ///< exposure time [s] (EuRoC VI-Sensor: a few ms)
  int blur_max_taps = 8;          ///< most samples along one pixel's motion
  /// Noise standard deviation at expected grey level I [grey levels].
  double sigmaAt(double grey) const;
  /// Reads keys under `prefix` (e.g. render.sensor.noise_sigma), then validates.
  Status read(const Config& c, const std::string& prefix = "render.sensor");
  Status validate() const;
  /// Writes every field under `prefix` (the configuration actually used).
  void write(ConfigWriter* w, const std::string& prefix = "render.sensor") const;
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
  std::vector<float> sigma_lut_;    ///< sigmaAt(i) for i = 0..256
};

/// SplitMix64 hash, used to derive independent seeds.
std::uint64_t mixSeed(std::uint64_t a, std::uint64_t b);

}  // namespace render
}  // namespace hermes
