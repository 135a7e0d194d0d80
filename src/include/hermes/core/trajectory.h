// Stamped pose sequences and TUM trajectory files
// (`timestamp[s] tx ty tz qx qy qz qw`, '#' comments), evo-compatible.
#pragma once

#include <string>
#include <vector>

#include "hermes/core/geometry.h"
#include "hermes/core/status.h"

namespace hermes {

struct StampedPose {
  double t = 0;  ///< [s]
  SE3 T_W_B;     ///< pose of the tracked frame (body or camera) in the world
};
using Trajectory = std::vector<StampedPose>;

/// Reads a TUM file. Errors name the path and line. Lines must be strictly
/// increasing in time after sorting is not attempted (unsorted input is an error).
Expected<Trajectory> readTumTrajectory(const std::string& path);
/// Writes a TUM file with full precision; error names the path.
Status writeTumTrajectory(const std::string& path, const Trajectory& traj);

/// Pose at time t by linear / slerp interpolation; false outside the span.
bool interpolatePose(const Trajectory& traj, double t, SE3* out);

/// Maps every pose through a fixed extrinsic: T_W_X = T_W_B * T_B_X.
Trajectory transformTrajectory(const Trajectory& traj, const SE3& T_B_X);

}  // namespace hermes
