// Image statistics for comparing rendered with real frames.
#include "hermes/core/image_stats.h"

#include <algorithm>
#include <cmath>

#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

namespace hermes {

namespace {

/// Sobel gradient magnitude / 8 (grey levels per pixel), CV_32F.
cv::Mat gradientMagnitude(const cv::Mat& grey) {
  cv::Mat gx, gy, mag;
  cv::Sobel(grey, gx, CV_32F, 1, 0, 3, 1.0 / 8.0);
  cv::Sobel(grey, gy, CV_32F, 0, 1, 3, 1.0 / 8.0);
  cv::magnitude(gx, gy, mag);
  return mag;
}

double median(std::vector<float>* v) {
  if (v->empty()) return 0;
  auto mid = v->begin() + static_cast<long>(v->size() / 2);
  std::nth_element(v->begin(), mid, v->end());
  return *mid;
}

/// Robust standard deviation of integer-valued differences: RMS about the
/// median after clipping beyond 4 MAD-sigmas (at least 3 levels). The MAD of
/// integers is itself an integer, too coarse for a sigma near 1 on its own.
double robustSigma(std::vector<float> v) {
  if (v.empty()) return 0;
  const double m = median(&v);
  std::vector<float> dev(v.size());
  for (std::size_t i = 0; i < v.size(); ++i) dev[i] = std::abs(v[i] - static_cast<float>(m));
  const double clip = std::max(3.0, 4.0 * 1.4826 * median(&dev));
  double ss = 0;
  long n = 0;
  for (float x : v) {
    const double d = x - m;
    if (std::abs(d) > clip) continue;
    ss += d * d;
    ++n;
  }
  return n ? std::sqrt(ss / n) : 0.0;
}

}  // namespace

NoiseFit temporalNoise(const std::vector<cv::Mat>& a, const std::vector<cv::Mat>& b, const NoiseOptions& o) {
  CV_Assert(a.size() == b.size());
  const int nbins = (255 + o.bin_width) / o.bin_width;
  std::vector<std::vector<float>> diff(nbins);
  std::vector<float> all;
  for (std::size_t k = 0; k < a.size(); ++k) {
    CV_Assert(a[k].type() == CV_8U && b[k].type() == CV_8U && a[k].size() == b[k].size());
    cv::Mat mean;
    cv::addWeighted(a[k], 0.5, b[k], 0.5, 0.0, mean, CV_32F);
    const cv::Mat mag = gradientMagnitude(mean);
    for (int v = 1; v + 1 < mean.rows; ++v) {
      const std::uint8_t* pa = a[k].ptr<std::uint8_t>(v);
      const std::uint8_t* pb = b[k].ptr<std::uint8_t>(v);
      const float* m = mean.ptr<float>(v);
      const float* g = mag.ptr<float>(v);
      for (int u = 1; u + 1 < mean.cols; ++u) {
        if (g[u] >= o.max_gradient || pa[u] == 0 || pb[u] == 0 || pa[u] == 255 || pb[u] == 255) continue;
        const float d = static_cast<float>(pa[u]) - static_cast<float>(pb[u]);
        diff[std::min(nbins - 1, static_cast<int>(m[u]) / o.bin_width)].push_back(d);
      }
    }
  }
  NoiseFit fit;
  // Per-bin robust sigma (bin median removed), then a weighted line fit of the variance.
  double sw = 0, sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (int i = 0; i < nbins; ++i) {
    const auto n = static_cast<long>(diff[i].size());
    fit.pixels += n;
    if (n == 0) continue;
    const double med = median(&diff[i]);
    for (float d : diff[i]) all.push_back(d - static_cast<float>(med));
    if (n < o.min_bin_pixels) continue;
    const double s = robustSigma(diff[i]) / std::sqrt(2.0);
    const double x = (i + 0.5) * o.bin_width, y = s * s, w = static_cast<double>(n);
    fit.bin_centre.push_back(x);
    fit.bin_sigma.push_back(s);
    sw += w, sx += w * x, sy += w * y, sxx += w * x * x, sxy += w * x * y;
  }
  fit.sigma = all.empty() ? 0 : robustSigma(all) / std::sqrt(2.0);
  const double den = sw * sxx - sx * sx;
  if (fit.bin_centre.size() >= 2 && den > 1e-9) {
    fit.photon_gain = (sw * sxy - sx * sy) / den;
    fit.read_var = (sy - fit.photon_gain * sx) / sw;
  } else if (sw > 0) {
    fit.read_var = sy / sw;
  }
  return fit;
}

std::vector<double> gradientHistogram(const cv::Mat& grey8, int bins, double bin_width) {
  CV_Assert(grey8.type() == CV_8U && bins >= 2 && bin_width > 0);
  const cv::Mat mag = gradientMagnitude(grey8);
  std::vector<double> h(bins, 0.0);
  for (int v = 1; v + 1 < mag.rows; ++v) {
    const float* g = mag.ptr<float>(v);
    for (int u = 1; u + 1 < mag.cols; ++u) h[std::min(bins - 1, static_cast<int>(g[u] / bin_width))] += 1;
  }
  double total = 0;
  for (double x : h) total += x;
  if (total > 0)
    for (double& x : h) x /= total;
  return h;
}

double hellinger(const std::vector<double>& p, const std::vector<double>& q) {
  CV_Assert(p.size() == q.size());
  double bc = 0;
  for (std::size_t i = 0; i < p.size(); ++i) bc += std::sqrt(p[i] * q[i]);
  return std::sqrt(std::max(0.0, 1.0 - bc));
}

std::vector<float> fastResponses(const cv::Mat& grey8, int threshold) {
  std::vector<cv::KeyPoint> kps;
  cv::FAST(grey8, kps, threshold, true);
  std::vector<float> r;
  r.reserve(kps.size());
  for (const cv::KeyPoint& k : kps) r.push_back(k.response);
  return r;
}

double ksDistance(std::vector<float> a, std::vector<float> b) {
  if (a.empty() || b.empty()) return 1.0;
  std::sort(a.begin(), a.end());
  std::sort(b.begin(), b.end());
  std::size_t i = 0, j = 0;
  double d = 0;
  while (i < a.size() && j < b.size()) {
    const float x = std::min(a[i], b[j]);
    while (i < a.size() && a[i] <= x) ++i;
    while (j < b.size() && b[j] <= x) ++j;
    d = std::max(d, std::abs(static_cast<double>(i) / a.size() - static_cast<double>(j) / b.size()));
  }
  return d;
}

double quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const double pos = std::clamp(q, 0.0, 1.0) * (v.size() - 1);
  const auto i = static_cast<std::size_t>(pos);
  if (i + 1 >= v.size()) return v.back();
  return v[i] + (pos - i) * (v[i + 1] - v[i]);
}

}  // namespace hermes
