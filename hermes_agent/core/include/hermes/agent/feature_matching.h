// Descriptor matching by projection: local-map landmarks are projected with a
// predicted camera pose and matched to the keypoints found in a radius around
// their projection (grid-indexed), by Hamming distance with a threshold and a
// ratio test; optionally only matches whose orientation change agrees with the
// dominant one are kept.
#pragma once

#include <string>
#include <vector>

#include "hermes/agent/orb_extractor.h"
#include "hermes/core/config.h"
#include "hermes/core/geometry.h"
#include "hermes/core/map_types.h"
#include "hermes/core/status.h"

namespace hermes {

/// Buckets keypoints on a regular grid for radius queries. Keeps a pointer to
/// `keypoints`, which must outlive the grid and not change.
class KeypointGrid {
 public:
  KeypointGrid(const std::vector<Keypoint>& keypoints, int width, int height, int cell_px = 16);
  /// Indices of keypoints within `radius` px of (u, v) whose octave lies in
  /// [min_octave, max_octave] (negative bounds = no limit).
  std::vector<int> query(double u, double v, double radius, int min_octave = -1,
                         int max_octave = -1) const;

 private:
  const std::vector<Keypoint>* keypoints_;
  int cell_, cols_, rows_;
  std::vector<std::vector<int>> cells_;
};

struct ProjectionMatchParams {
  double radius_px = 12.0;        ///< search radius around the projection [px at level 0]
  int max_hamming = 60;           ///< accept up to this distance [bits]
  double ratio = 0.8;             ///< best < ratio * second best
  bool check_orientation = true;  ///< keep only the dominant rotation (needs landmark angles)
  int orientation_bins = 30;      ///< histogram bins over 360 deg
  double min_depth = 0.05;        ///< landmarks closer to the camera are skipped [m]

  Status read(const Config& config, const std::string& prefix = "matching");
  void write(ConfigWriter* writer, const std::string& prefix = "matching") const;
  Status validate() const;
};

/// A landmark as seen by the matcher.
struct LandmarkView {
  Vec3 p_W = Vec3::Zero();  ///< position in the map frame [m]
  Descriptor descriptor{};
  float angle = -1.f;       ///< keypoint angle when last observed [deg], < 0 if unknown
};

/// For every landmark, the index of its matched keypoint in `frame` or -1.
/// Each keypoint is used at most once (the closer descriptor wins).
std::vector<int> matchByProjection(const std::vector<LandmarkView>& landmarks,
                                   const SE3& T_C_W, const PinholeIntrinsics& K,
                                   const FeatureSet& frame, const KeypointGrid& grid,
                                   const ProjectionMatchParams& params);

/// The same without a pose (relocalisation): every landmark against every
/// keypoint (radius and min_depth unused).
std::vector<int> matchByDescriptor(const std::vector<LandmarkView>& landmarks,
                                   const FeatureSet& frame, const ProjectionMatchParams& params);

}  // namespace hermes
