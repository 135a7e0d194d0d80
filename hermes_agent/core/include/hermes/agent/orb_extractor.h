// ORB features spread evenly over the image: an image pyramid, FAST corners
// detected per grid cell with an adaptive threshold, a per-level budget,
// grid bucketing with response ranking, orientation by intensity centroid and
// rBRIEF descriptors (OpenCV's ORB descriptor on our keypoints). Keypoint
// coordinates are returned at pyramid level 0 (and optionally undistorted).
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>

#include "hermes/core/camera.h"
#include "hermes/core/config.h"
#include "hermes/core/map_types.h"
#include "hermes/core/status.h"

namespace hermes {

struct OrbParams {
  int num_features = 1000;     ///< total budget over all levels
  int num_levels = 8;          ///< pyramid levels
  double scale_factor = 1.2;   ///< size ratio between consecutive levels
  int fast_threshold = 20;     ///< initial FAST threshold [grey levels]
  int fast_min_threshold = 7;  ///< retry threshold for cells without corners
  int cell_size = 32;          ///< FAST detection cell edge [px, at each level]
  int edge_threshold = 19;     ///< no keypoint closer than this to a level's border [px]

  /// Reads keys under `prefix` (e.g. "orb.num_features"); missing keys keep defaults.
  Status read(const Config& config, const std::string& prefix = "orb");
  void write(ConfigWriter* writer, const std::string& prefix = "orb") const;
  Status validate() const;
};

/// Features of one image. All vectors have the same length.
struct FeatureSet {
  std::vector<Keypoint> keypoints;      ///< level-0 coordinates (u, v, octave)
  std::vector<Descriptor> descriptors;  ///< 256-bit rBRIEF
  std::vector<float> angles;            ///< orientation [deg, 0..360)
  std::vector<float> responses;         ///< FAST score
  std::vector<cv::Mat> pyramid;         ///< grey level images (shared, not copied)
  std::vector<float> scales;            ///< scale of each level w.r.t. level 0
  int width = 0, height = 0;            ///< level-0 image size

  std::size_t size() const { return keypoints.size(); }
  /// Level-0 coordinates of the point (x, y) given in level `level`'s pixels.
  /// The levels are resampled with pixel centres aligned (cv::resize), so a
  /// level pixel x covers level-0 x0 = (x + 0.5) * W0 / Wl - 0.5 (per axis, the
  /// levels' real sizes, not the nominal scale). Without the pyramid (decoded
  /// features) the nominal scale is used with the same centre alignment.
  cv::Point2d toBase(int level, double x, double y) const;
  /// The inverse of toBase: level-`level` pixel coordinates of a level-0 point.
  cv::Point2d toLevel(int level, double u, double v) const;

 private:
  cv::Point2d levelRatio(int level) const;
};

class OrbExtractor {
 public:
  explicit OrbExtractor(const OrbParams& params = OrbParams());

  /// Extracts features from an 8-bit grey (or BGR, converted) image.
  /// Errors: empty image, unsupported type, image smaller than the border.
  Expected<FeatureSet> extract(const cv::Mat& image) const;

  const OrbParams& params() const { return params_; }
  /// Number of features assigned to each level (sums to num_features).
  const std::vector<int>& levelBudget() const { return budget_; }

 private:
  void detectLevel(const cv::Mat& level, int octave, std::vector<cv::KeyPoint>* out) const;

  OrbParams params_;
  std::vector<float> scales_;
  std::vector<int> budget_;
  std::vector<int> umax_;  // half-widths of the circular orientation patch per row
  cv::Ptr<cv::Feature2D> describer_;  // cv::ORB used for rBRIEF only (stateless in compute)
};

/// Replaces distorted keypoint coordinates by undistorted ones in the pixel frame
/// of `out` (for cameras whose images are not rectified beforehand).
void undistortKeypoints(const PinholeRadtan& camera, const PinholeIntrinsics& out,
                        FeatureSet* features);

/// Builds a pyramid of `levels` images, each `scale` smaller than the previous
/// (sizes rounded like cv::ORB's, bilinear resampling).
std::vector<cv::Mat> buildPyramid(const cv::Mat& grey, int levels, double scale);

}  // namespace hermes
