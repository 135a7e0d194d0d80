// Internal to the loop closer: maximum-likelihood refinement of the generalized
// relative pose (small bundle adjustment over the pose and the inliers' points,
// Ceres) and the pose information by Schur complement of the points.
#pragma once

#include <string>
#include <vector>

#include "hermes/server/loop_closure.h"

namespace hermes {
namespace server {
namespace detail {

struct Refinement {
  bool ok = false;
  std::string reason;          ///< why the information could not be formed
  SE3 T_refQ_refC;
  std::vector<int> inliers;    ///< within the pixel threshold after refinement
  int depth_inliers = 0;       ///< of which with a measured depth in at least one view
  Mat6 information = Mat6::Zero();
  Mat6 covariance = Mat6::Zero();
  double sigma_px = 0;         ///< pixel noise used for the information
  int iterations = 0;
};

/// Triangulates the inliers with T0, optionally runs the bundle adjustment
/// (params.refine), re-selects inliers by reprojection error and forms the
/// information of the right perturbation T * exp(xi), xi = [rho; phi].
Refinement refineGeneralizedPose(const GeneralizedCorrespondences& corr,
                                 const std::vector<int>& inliers, const SE3& T0,
                                 const LoopClosureParams& params);

/// Largest translation sigma [m] of the loop at pose T with the inliers
/// triangulated there (no refinement), at the floor pixel noise and from at most
/// max_points evenly spaced inliers (information scaled to all): about a lower
/// bound of what refineGeneralizedPose reports for these inliers (it keeps a
/// subset, its noise is at least the floor), to reject a weak loop before it.
double translationSigmaBound(const GeneralizedCorrespondences& corr, const std::vector<int>& inliers,
                             const SE3& T, const LoopClosureParams& params, int max_points);

}  // namespace detail
}  // namespace server
}  // namespace hermes
