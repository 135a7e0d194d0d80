// Stereo matching on rectified pairs: for every left keypoint, the right
// keypoints on the same row band (±row_band px scaled by octave) inside the
// disparity range are compared by Hamming distance (threshold + ratio check);
// the winner is refined to sub-pixel precision by zero-mean SAD correlation of
// a patch along the row at the keypoint's pyramid level plus a sub-pixel fit of
// the cost around its minimum (equiangular "V" fit by default: SAD is V-shaped and
// the parabola locks onto integer shifts, ~0.1 px bias; "parabola" selectable),
// then the same refinement again on level 0 (coarse-to-fine).
// Depth = fx * b / d. Bad disparities and SAD outliers are rejected.
#pragma once

#include <string>
#include <vector>

#include "hermes/agent/orb_extractor.h"
#include "hermes/core/config.h"
#include "hermes/core/map_types.h"
#include "hermes/core/status.h"

namespace hermes {

struct StereoParams {
  int max_hamming = 75;          ///< accept a descriptor match up to this distance [bits]
  double ratio = 0.9;            ///< best < ratio * second best (distinct candidates)
  double row_band_px = 2.0;      ///< row tolerance at level 0, times the octave scale [px]
  double min_depth = 0.1;        ///< nearest accepted depth [m]
  double max_depth = 60.0;       ///< farthest accepted depth [m]
  int sad_half_window = 5;       ///< SAD patch half size at the keypoint's level [px]
  int sad_search_radius = 5;     ///< integer shifts tried around the right keypoint [px]
  double sad_outlier_factor = 2.1;  ///< reject SAD cost > factor * median cost
  std::string subpixel_fit = "equiangular";  ///< equiangular | parabola

  Status read(const Config& config, const std::string& prefix = "stereo");
  void write(ConfigWriter* writer, const std::string& prefix = "stereo") const;
  Status validate() const;
};

struct StereoResult {
  std::vector<float> u_right;    ///< per left keypoint, refined right column, -1 if none
  std::vector<float> disparity;  ///< per left keypoint [px], 0 if none
  int matched = 0;
};

/// Matches `left` against `right` (both from the same OrbExtractor settings on a
/// rectified pair with intrinsics K and baseline [m]) and writes the metric depth
/// into left->keypoints[i].depth (0 when unmatched). Errors: inconsistent inputs.
Expected<StereoResult> matchStereo(FeatureSet* left, const FeatureSet& right,
                                   const PinholeIntrinsics& K, double baseline,
                                   const StereoParams& params);

/// Sub-pixel refinement alone: the column in `right_level` best matching the patch
/// around (x_left, y) of `left_level` near integer column x_right0 (all at one
/// pyramid level). Returns false if the patch leaves the image or the minimum
/// lies on the search border; *cost receives the best zero-mean SAD.
bool refineDisparitySad(const cv::Mat& left_level, const cv::Mat& right_level, int x_left,
                        int y, int x_right0, int half_window, int search_radius,
                        double* x_right, double* cost, bool parabola = false);

}  // namespace hermes
