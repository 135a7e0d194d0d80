// Realistic distillation windows built from a ground-truth trajectory (no
// images): landmarks spread on the walls, floor and ceiling of a box around the
// trajectory, keyframes every keyframe_period_s, observations = noisy projections
// inside a 752×480 pinhole image (EuRoC cam0 intrinsics), random ORB-like
// descriptors, plus unlinked keypoints. The box is convex and the camera inside,
// so there is no occlusion. Deterministic for a seed. Used by tests and by
// hermes_bench_distill.
#pragma once

#include <cstdint>
#include <random>
#include <vector>

#include "hermes/core/map_types.h"
#include "hermes/core/status.h"
#include "hermes/core/trajectory.h"
#include "hermes/distill/scores.h"

namespace hermes {
namespace distill {

/// EuRoC cam0 body <- camera (T_BS of cam0's sensor.yaml).
SE3 eurocCam0TBC();
/// EuRoC cam0 pinhole (458.654, 457.296, 367.215, 248.375), 752×480.
PinholeIntrinsics eurocCam0Intrinsics();

struct SyntheticWindowParams {
  double duration_s = 5.0;
  double keyframe_period_s = 0.5;
  double landmarks_per_m2 = 12.0;
  double box_margin_m = 2.0;
  double max_depth_m = 15.0;
  int max_observations_per_kf = 500;  ///< strongest (nearest) projections kept
  double unlinked_fraction = 0.3;     ///< extra keypoints without landmark
  double pixel_noise = 0.7;           ///< [px]
  double landmark_noise_m = 0.02;     ///< error of the mapped position [m]
  std::uint64_t seed = 1;
};

struct SyntheticWindow {
  Submap submap;
  MotionHint hint;
};

class SyntheticScene {
 public:
  /// trajectory: body poses in the world (e.g. EuRoC ground truth).
  SyntheticScene(Trajectory trajectory, const SyntheticWindowParams& params,
                 SE3 T_B_C = eurocCam0TBC(), PinholeIntrinsics camera = eurocCam0Intrinsics());

  /// Window starting t_start_s seconds after the trajectory's first pose;
  /// error when the window leaves the trajectory.
  Expected<SyntheticWindow> window(double t_start_s, std::uint64_t seq) const;

  double duration() const;
  const std::vector<Vec3>& landmarks() const { return points_; }

 private:
  Trajectory traj_;
  SyntheticWindowParams params_;
  SE3 T_B_C_;
  PinholeIntrinsics cam_;
  std::vector<Vec3> points_;
  std::vector<Descriptor> descriptors_;
};

/// A deterministic stand-in for the wire encoder's size (header, cameras,
/// keyframes with pose/odometry, keypoints with descriptors and links,
/// landmarks with descriptors, observations), for tests and benchmarks until the
/// real encoder is plugged in through Distiller's size function.
std::size_t referenceEncodedSize(const Submap& submap);

/// Loads a TUM trajectory and builds the scene.
Expected<SyntheticScene> makeSceneFromTum(const std::string& path,
                                          const SyntheticWindowParams& params);

}  // namespace distill
}  // namespace hermes
