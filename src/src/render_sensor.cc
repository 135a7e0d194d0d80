// Sensor model: exposure drift and steps, vignetting, read noise, quantisation.
#include "hermes/core/render/sensor.h"

#include <algorithm>
#include <cmath>

namespace hermes {
namespace render {

std::uint64_t mixSeed(std::uint64_t a, std::uint64_t b) {
  std::uint64_t z = a * 0x9e3779b97f4a7c15ULL + b + 0x632be59bd9b4e019ULL;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

namespace {
double unit(std::uint64_t h) { return static_cast<double>(h >> 11) * (1.0 / 9007199254740992.0); }
}  // namespace

Status SensorParams::read(const Config& c, const std::string& prefix) {
  for (Status st : {c.get(prefix + ".noise_sigma", &noise_sigma), c.get(prefix + ".vignetting", &vignetting),
                    c.get(prefix + ".brightness", &brightness),
                    c.get(prefix + ".drift_amplitude", &drift_amplitude),
                    c.get(prefix + ".step_amplitude", &step_amplitude),
                    c.get(prefix + ".step_period_s", &step_period_s),
                    c.get(prefix + ".step_probability", &step_probability), c.get(prefix + ".noise", &noise),
                    c.get(prefix + ".photon_noise", &photon_noise), c.get(prefix + ".photon_gain", &photon_gain),
                    c.get(prefix + ".motion_blur", &motion_blur), c.get(prefix + ".exposure_s", &exposure_s),
                    c.get(prefix + ".blur_max_taps", &blur_max_taps)})
    if (!st) return st;
  if (Status st = validate(); !st) return Error{st.error() + " (" + c.origin() + ")"};
  return Status::Ok();
}

Status SensorParams::validate() const {
  if (!(noise_sigma >= 0 && noise_sigma < 50)) return Error{"sensor: noise_sigma must be in [0, 50)"};
  if (!(brightness > 0.05 && brightness <= 20)) return Error{"sensor: brightness must be in (0.05, 20]"};
  if (!(vignetting >= 0 && vignetting < 1)) return Error{"sensor: vignetting must be in [0, 1)"};
  if (!(drift_amplitude >= 0 && drift_amplitude < 1)) return Error{"sensor: drift_amplitude must be in [0, 1)"};
  if (!(step_amplitude >= 0 && step_amplitude < 1)) return Error{"sensor: step_amplitude must be in [0, 1)"};
  if (!(step_period_s > 1)) return Error{"sensor: step_period_s must be > 1"};
  if (!(step_probability >= 0 && step_probability <= 1))
    return Error{"sensor: step_probability must be in [0, 1]"};
  if (!(photon_gain >= 0 && photon_gain <= 10)) return Error{"sensor: photon_gain must be in [0, 10]"};
  if (!(exposure_s > 0 && exposure_s <= 0.05)) return Error{"sensor: exposure_s must be in (0, 0.05] s"};
  if (blur_max_taps < 2 || blur_max_taps > 64) return Error{"sensor: blur_max_taps must be in [2, 64]"};
  return Status::Ok();
}

void SensorParams::write(ConfigWriter* w, const std::string& prefix) const {
  w->set(prefix + ".noise_sigma", noise_sigma);
  w->set(prefix + ".brightness", brightness);
  w->set(prefix + ".vignetting", vignetting);
  w->set(prefix + ".drift_amplitude", drift_amplitude);
  w->set(prefix + ".step_amplitude", step_amplitude);
  w->set(prefix + ".step_period_s", step_period_s);
  w->set(prefix + ".step_probability", step_probability);
  w->set(prefix + ".noise", noise);
  w->set(prefix + ".photon_noise", photon_noise);
  w->set(prefix + ".photon_gain", photon_gain);
  w->set(prefix + ".motion_blur", motion_blur);
  w->set(prefix + ".exposure_s", exposure_s);
  w->set(prefix + ".blur_max_taps", blur_max_taps);
}

double SensorParams::sigmaAt(double grey) const {
  if (!noise) return 0.0;
  const double var = noise_sigma * noise_sigma + (photon_noise ? photon_gain * std::max(grey, 0.0) : 0.0);
  return std::sqrt(var);
}

Sensor::Sensor(const SensorParams& p, std::uint64_t seed, int width, int height) : p_(p), seed_(seed) {
  cv::Mat table(1, 1 << 21, CV_32F);
  cv::RNG table_rng(mixSeed(seed, 0x401));
  table_rng.fill(table, cv::RNG::NORMAL, 0.0, 1.0);
  noise_table_.assign(table.ptr<float>(), table.ptr<float>() + table.cols);
  for (int i = 0; i <= 256; ++i) sigma_lut_.push_back(static_cast<float>(p_.sigmaAt(i)));
  vignette_.create(height, width, CV_32F);
  const double cx = 0.5 * (width - 1), cy = 0.5 * (height - 1);
  const double r2max = cx * cx + cy * cy;
  for (int v = 0; v < height; ++v)
    for (int u = 0; u < width; ++u) {
      const double r2 = ((u - cx) * (u - cx) + (v - cy) * (v - cy)) / r2max;
      vignette_.at<float>(v, u) = static_cast<float>(1.0 - p_.vignetting * r2 * (0.6 + 0.4 * r2));
    }
}

double Sensor::stepLevel(std::int64_t k) const {
  const std::uint64_t h = mixSeed(seed_ ^ 0x5bd1e995ULL, static_cast<std::uint64_t>(k));
  if (unit(h) >= p_.step_probability) return 0.0;
  return p_.step_amplitude * (2.0 * unit(mixSeed(h, 7)) - 1.0);
}

double Sensor::gain(double t) const {
  const double ph1 = 6.283185307 * unit(mixSeed(seed_, 11));
  const double ph2 = 6.283185307 * unit(mixSeed(seed_, 12));
  const double drift = p_.drift_amplitude * (0.7 * std::sin(6.283185307 * t / 37.0 + ph1) +
                                             0.3 * std::sin(6.283185307 * t / 11.3 + ph2));
  const double kf = std::floor(t / p_.step_period_s);
  const auto k = static_cast<std::int64_t>(kf);
  const double since = t - kf * p_.step_period_s;
  const double a = std::clamp(since / 0.5, 0.0, 1.0);  // 0.5 s auto-exposure transition
  const double s = a * a * (3 - 2 * a);
  const double step = (1 - s) * stepLevel(k - 1) + s * stepLevel(k);
  return p_.brightness * std::exp(drift + step);
}

cv::Mat Sensor::expose(const cv::Mat& radiance, double t, int cam) const {
  const float g = static_cast<float>(gain(t) * (cam == 0 ? 1.0 : 0.97));
  // Noise: a per-frame odd stride walk through a fixed table of N(0,1) samples
  // (a permutation of the table, so no sample repeats within a frame).
  const bool noisy = p_.noise && (p_.noise_sigma > 0 || (p_.photon_noise && p_.photon_gain > 0));
  const bool photon = p_.photon_noise;
  const auto tns = static_cast<std::uint64_t>(std::llround(t * 1e6));  // us: frame identity
  const std::uint64_t h = mixSeed(mixSeed(seed_, tns), static_cast<std::uint64_t>(cam) + 100);
  const std::uint32_t mask = static_cast<std::uint32_t>(noise_table_.size() - 1);
  std::uint32_t idx = static_cast<std::uint32_t>(h) & mask;
  const std::uint32_t stride = (static_cast<std::uint32_t>(h >> 32) | 1u) & mask;
  const float sigma = static_cast<float>(p_.noise_sigma);
  cv::Mat out(radiance.size(), CV_8U);
  for (int v = 0; v < radiance.rows; ++v) {
    const float* r = radiance.ptr<float>(v);
    const float* vg = vignette_.ptr<float>(v);
    std::uint8_t* o = out.ptr<std::uint8_t>(v);
    for (int u = 0; u < radiance.cols; ++u) {
      float x = r[u] * g * vg[u] + 0.5f;
      if (noisy) {
        // Photon noise: sigma from the expected level (clamped to the LUT range).
        const float sg = photon ? sigma_lut_[static_cast<int>(std::min(std::max(x, 0.0f), 256.0f))] : sigma;
        x += sg * noise_table_[idx];
        idx = (idx + stride) & mask;
      }
      x = std::min(std::max(x, 0.0f), 255.0f);
      o[u] = static_cast<std::uint8_t>(x);
    }
  }
  return out;
}

}  // namespace render
}  // namespace hermes
