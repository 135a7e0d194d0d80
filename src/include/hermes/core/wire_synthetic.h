// Deterministic synthetic submaps with realistic structure (keyframes moving
// through a scene, landmarks projected into them, ORB-like descriptors), for the
// wire-format tests and benchmarks and for anyone who needs a plausible Submap.
#pragma once

#include <cstdint>

#include "hermes/core/map_types.h"

namespace hermes {

struct SyntheticSubmapOptions {
  int keyframes = 10;
  int keypoints_per_keyframe = 800;  ///< matched + unmatched keypoints per keyframe
  int landmarks = 3000;
  double observe_probability = 0.35;  ///< chance a visible landmark is observed in a keyframe
  double matched_fraction = 0.6;      ///< at most this share of a keyframe's keypoints see landmarks
  int cameras = 1;
  bool random_ids = false;  ///< arbitrary 64-bit ids instead of increasing ones
  std::uint64_t seed = 1;
};

/// Builds a valid submap (validate() passes; keypoint_landmark agrees with the
/// landmarks' observations; odometry joins consecutive keyframes).
Submap makeSyntheticSubmap(const SyntheticSubmapOptions& options);

}  // namespace hermes
