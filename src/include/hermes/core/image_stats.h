// Image statistics that compare rendered with real camera frames: temporal
// noise of a static scene as a function of intensity, gradient-magnitude
// histograms and their distance, FAST corners and their responses.
#pragma once

#include <vector>

#include <opencv2/core.hpp>

namespace hermes {

/// Temporal noise from frame pairs of a static scene: d = a - b on flat
/// pixels (gradient below a threshold, not saturated), robust sigma per
/// intensity bin (RMS about the median, clipped at 4 MAD-sigmas, / sqrt 2; bin median removed so small exposure
/// changes do not count), and the fit sigma^2(I) = read_var + photon_gain * I.
struct NoiseFit {
  double sigma = 0;        ///< over all flat pixels [grey levels]
  double read_var = 0;     ///< fitted intercept [grey levels^2]
  double photon_gain = 0;  ///< fitted slope [grey levels^2 per grey level]
  long pixels = 0;         ///< flat pixels used
  std::vector<double> bin_centre, bin_sigma;  ///< bins with enough pixels
};

struct NoiseOptions {
  float max_gradient = 6.0f;  ///< flat: Sobel magnitude / 8 below this [grey levels per px]
  int bin_width = 16;         ///< intensity bin [grey levels]
  int min_bin_pixels = 400;   ///< bins with fewer pixels are left out of the fit
};

NoiseFit temporalNoise(const std::vector<cv::Mat>& a, const std::vector<cv::Mat>& b,
                       const NoiseOptions& o = NoiseOptions());

/// Normalised histogram of the Sobel gradient magnitude (|grad| / 8, grey
/// levels per pixel) in `bins` bins of `bin_width`; the last bin holds the rest.
std::vector<double> gradientHistogram(const cv::Mat& grey8, int bins = 32, double bin_width = 2.0);

/// Hellinger distance between two normalised histograms (0 = same, 1 = disjoint).
double hellinger(const std::vector<double>& p, const std::vector<double>& q);

/// FAST corners (non-maximum suppressed) at `threshold` and their responses.
std::vector<float> fastResponses(const cv::Mat& grey8, int threshold);

/// Two-sample Kolmogorov-Smirnov statistic (0 = same distribution).
double ksDistance(std::vector<float> a, std::vector<float> b);

/// q-quantile (0..1) of the values (linear interpolation); 0 when empty.
double quantile(std::vector<double> v, double q);

}  // namespace hermes
