// Map refinement after merging (issue 16 item 3): a windowed bundle adjustment
// (Ceres) around loops that tie keyframes together, so that the merged map is
// metrically consistent in its landmarks too, not only in its pose graph.
//
// Window: for each given loop, its two keyframes and `neighbours` keyframes on
// each side in their trajectories (and the rig keyframes its kept inlier pairs
// name) are free; the landmarks they observe are free; every other anchored
// keyframe observing those landmarks is in the problem but held (fixed outer
// keyframes: they fix the gauge and keep the window tied to the rest of the map).
// Residuals: reprojection of each landmark into each observing keyframe [px,
// whitened by the keypoint's pyramid level], its measured depth (stereo / RGB-D)
// as a disparity residual fb * (1/z - 1/d), and the cross-robot ties: a loop's
// kept inlier pair whose keypoint on one side has a landmark is an observation
// of that landmark by the other side's keyframe. Robust loss on all of them.
//
// Write-back: free keyframes' T_W_C and free landmarks' p_anchor. For the pose
// graph not to undo it at its next solve, the relative poses of the pose-graph
// edges inside the window (consecutive keyframes of one trajectory, accepted
// loops) are stored in GlobalMap::refined_edges and used by the pose graph in
// place of their measurements (same information); new keyframes follow the
// refined poses (MapManager::storeSubmap), odometry outside windows is untouched.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "hermes/core/config.h"
#include "hermes/core/geometry.h"
#include "hermes/core/map_types.h"
#include "hermes/core/status.h"
#include "hermes/server/global_map.h"

namespace hermes {
namespace server {

struct MapRefinementParams {
  bool enabled = false;              ///< run after merges that accepted new loops
  int ties_per_loop = 200;           ///< inlier keypoint pairs kept per loop edge (evenly spaced; 0 = none)
  int neighbours = 4;                ///< [keyframes] free on each side of a loop keyframe
  int max_loops = 8;                 ///< newest new loops per window at most
  int max_free_keyframes = 60;       ///< free keyframes per window at most
  int max_fixed_keyframes = 60;      ///< held outer keyframes per window at most
  int min_keyframe_residuals = 10;   ///< free keyframes with fewer observations are held
  double pixel_sigma_px = 1.0;       ///< [px] keypoint noise at pyramid level 0
  double octave_scale = 1.2;         ///< pyramid scale factor (sigma x scale^octave)
  double depth_focal_baseline_px_m = 45.0;  ///< [px m] depth residuals in disparity pixels; 0 = no depths
  std::string loss = "huber";        ///< none | huber | cauchy
  double loss_scale = 2.0;           ///< [sigma] robust loss scale on the whitened residual
  int max_iterations = 15;           ///< Levenberg-Marquardt iterations per window
  /// [s] solver wall-time budget per window; 0 = none (the iteration cap only):
  /// a wall-time limit makes the merged map depend on the machine's load.
  double max_time_s = 0;
  double max_pose_change_m = 0.10;   ///< [m] a solution moving a keyframe further is discarded
  /// Store the window's relative poses in GlobalMap::refined_edges (the pose
  /// graph keeps them); false: the refined poses are only the next solve's start.
  bool keep_in_pose_graph = true;
  /// Odometry edges (the agents' own, as received) between consecutive keyframes
  /// of the window as relative-pose residuals, information x this (0 = none):
  /// the server holds only the distilled landmarks, fewer than the agent's
  /// local BA used for those relative poses.
  double odometry_weight = 1.0;

  Status read(const Config& config, const std::string& prefix);
  void write(ConfigWriter* writer, const std::string& prefix) const;
  Status validate() const;
};

struct MapRefinementResult {
  bool ran = false;           ///< a problem was built and solved
  bool applied = false;       ///< the solution was written back
  std::string termination;    ///< Ceres' termination type, or why nothing ran
  int iterations = 0;
  int free_keyframes = 0, fixed_keyframes = 0, landmarks = 0;
  int residuals = 0, ties = 0, odometry = 0;
  double initial_cost = 0, final_cost = 0;
  double max_pose_change_m = 0;
  double time_ms = 0;
};

/// Refines the window around `loop_ids` (accepted loops between anchored
/// trajectories; others are skipped) and writes it back when the solve is usable.
MapRefinementResult refineAroundLoops(GlobalMap* map, const std::vector<std::uint64_t>& loop_ids,
                                      const MapRefinementParams& params);

/// Map-consistency measure over the accepted loops' kept keypoint pairs: each
/// side's landmark (world position) against the other side's keypoint, as a
/// reprojection error [px] and, where that keypoint has a depth, as a 3-D
/// distance to its back-projection [m]. Cross-robot pairs and all pairs.
struct TieConsistency {
  int ties = 0, cross_ties = 0;
  double reproj_rms_px = 0, cross_reproj_rms_px = 0, cross_reproj_median_px = 0;
  int depth_ties = 0, cross_depth_ties = 0;
  double dist_rms_m = 0, cross_dist_rms_m = 0, cross_dist_median_m = 0;
};
TieConsistency measureLoopTies(const GlobalMap& map, double max_reproj_px = 50.0);

namespace detail {
/// p_C = R^T (p_W - t) for the camera T_W_C = (q (Eigen x,y,z,w), t).
template <typename T>
Eigen::Matrix<T, 3, 1> pointInCamera(const T* q, const T* t, const T* p) {
  const Eigen::Map<const Eigen::Quaternion<T>> q_W_C(q);
  return q_W_C.conjugate() *
         (Eigen::Map<const Eigen::Matrix<T, 3, 1>>(p) - Eigen::Map<const Eigen::Matrix<T, 3, 1>>(t));
}

/// Reprojection residual of world point p_W in camera T_W_C = (q, t):
/// (project(R^T (p_W - t)) - uv) / sigma. Parameters q (Eigen x,y,z,w), t, p_W.
struct ReprojectionCost {
  double u, v, fx, fy, cx, cy, inv_sigma;
  template <typename T>
  bool operator()(const T* q, const T* t, const T* p, T* r) const {
    const Eigen::Matrix<T, 3, 1> p_C = pointInCamera(q, t, p);
    if (p_C.z() < T(1e-6)) {  // behind the camera: a large, smooth penalty
      r[0] = r[1] = T(1e3);
      return true;
    }
    r[0] = (T(fx) * p_C.x() / p_C.z() + T(cx) - T(u)) * T(inv_sigma);
    r[1] = (T(fy) * p_C.y() / p_C.z() + T(cy) - T(v)) * T(inv_sigma);
    return true;
  }
};

/// Depth residual in disparity pixels: fb * (1 / z - 1 / depth) / sigma.
struct InverseDepthCost {
  double inv_depth, fb, inv_sigma;
  template <typename T>
  bool operator()(const T* q, const T* t, const T* p, T* r) const {
    const Eigen::Matrix<T, 3, 1> p_C = pointInCamera(q, t, p);
    if (p_C.z() < T(1e-6)) {
      r[0] = T(1e3);
      return true;
    }
    r[0] = T(fb) * (T(1) / p_C.z() - T(inv_depth)) * T(inv_sigma);
    return true;
  }
};
}  // namespace detail

}  // namespace server
}  // namespace hermes
