// Map-consistency measure of a merged map: the accepted loops' kept inlier
// keypoint pairs (server.map.ties_per_loop, saved with the map) tie a landmark
// of one side to a keypoint of the other; each side's landmark (world
// position) is projected into the other side's keyframe and compared with the
// keypoint, as a reprojection error [px] and, where the keypoint has a depth,
// as a 3-D distance to its back-projection [m]. A map whose robots agree
// metrically has small cross-robot ties. Read by hermes_map_consistency.
#pragma once

#include "hermes/server/global_map.h"

namespace hermes {
namespace server {

/// Over the accepted loops' kept pairs: all pairs and the cross-robot ones.
struct TieConsistency {
  int ties = 0, cross_ties = 0;
  double reproj_rms_px = 0, cross_reproj_rms_px = 0, cross_reproj_median_px = 0;
  int depth_ties = 0, cross_depth_ties = 0;
  double dist_rms_m = 0, cross_dist_rms_m = 0, cross_dist_median_m = 0;
};

/// Ties whose reprojection error exceeds max_reproj_px are left out (a wrong
/// match or landmark, not the map's consistency).
TieConsistency measureLoopTies(const GlobalMap& map, double max_reproj_px = 50.0);

}  // namespace server
}  // namespace hermes
