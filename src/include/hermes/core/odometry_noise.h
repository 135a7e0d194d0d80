// Odometry noise: ONE model for the uncertainty of the relative pose between
// two keyframes of one robot, used by the agent (edges of a window), the
// distiller (edges across trimmed keyframes) and the server (bridges between
// windows, PCM, pose graph). Configuration keys `odometry.*`.
//
// Visual odometry error behaves like a random walk in the distance travelled
// and the rotation turned, so the VARIANCE of an edge grows linearly with them:
//   σt² = trans_floor_m² + trans_per_sqrt_m² · d + trans_per_sqrt_rad² · θ
//   σr² = rot_floor_rad² + rot_per_sqrt_m²   · d + rot_per_sqrt_rad²   · θ
// with d = ‖t_a_b‖ [m] and θ = angle(R_a_b) [rad]; covariance
// diag(σt² I₃, σr² I₃) of the right perturbation T_a_b·exp([ρ; φ]). Splitting an
// edge in two then gives (up to the floors) the same variance as one edge, and
// composing edges (composeEdges) propagates rotation noise into translation
// through the adjoint, so long chains drift like real odometry does.
//
// The defaults are fitted (scripts/fit_odometry_noise.py) to the stereo odometry
// of whole rendered MH_01, MH_02, MH_04 and MH_05 (0.3-10 m spans: 0.0059 m/sqrt(m),
// 0.010 m/sqrt(rad), 0.00061 rad/sqrt(m), 0.0013 rad/sqrt(rad)), with a 1.5x
// margin on each sigma for images harder than the renders.
//
// Tracking quality scales it: an edge whose keyframes share n landmarks gets
// covariance / clamp(n / shared_ref, min_weight, 1); an edge across lost frames
// (the tracker relocalised between the two keyframes) × lost_inflation. A
// relocalisation's error is not a random walk: the default (1e6, sigmas x1000)
// makes such an edge as good as unknown, so PCM does not judge loops through it
// and the pose graph lets the loops place the two sides (x100 before: on whole
// MH_01-05 with MH_03 jumping 0.5 m / 10 deg, 23 of MH_03's own right loops
// across the jump were rejected and the others' merged error grew 1.26x; now 5
// rejected in all, MH_03 1.01 cm, every other robot within 1.08x).
#pragma once

#include <utility>
#include <vector>

#include "hermes/core/config.h"
#include "hermes/core/geometry.h"
#include "hermes/core/status.h"

namespace hermes {

struct OdometryNoiseParams {
  double trans_floor_m = 0.001;       ///< [m] translation sigma of a standing edge
  double trans_per_sqrt_m = 0.009;     ///< [m/sqrt(m)] translation random walk per metre
  double trans_per_sqrt_rad = 0.015;  ///< [m/sqrt(rad)] translation random walk per radian
  double rot_floor_rad = 0.0002;      ///< [rad] rotation sigma of a standing edge
  double rot_per_sqrt_m = 0.001;      ///< [rad/sqrt(m)] rotation random walk per metre
  double rot_per_sqrt_rad = 0.002;     ///< [rad/sqrt(rad)] rotation random walk per radian
  int shared_ref = 50;                ///< shared landmarks at which the model applies as is
  double min_weight = 0.05;           ///< weakest quality weight (fewest shared landmarks)
  double lost_inflation = 1e6;        ///< covariance factor of an edge across lost frames (sigma x1000: unknown)

  /// Keys under "odometry." (a missing key keeps its default).
  Status read(const Config& config);
  void write(ConfigWriter* writer) const;
  Status validate() const;
};

/// Covariance (6x6, [rho; phi], right perturbation) of the relative pose T_a_b
/// measured by odometry with `shared` landmarks in common (< 0: unknown, the
/// model as is) and `lost` frames between (the tracker relocalised).
Mat6 odometryCovariance(const SE3& T_a_b, int shared, bool lost, const OdometryNoiseParams& params);
/// Its inverse.
Mat6 odometryInformation(const SE3& T_a_b, int shared, bool lost, const OdometryNoiseParams& params);

/// One relative pose with the covariance of its right perturbation.
struct RelativePoseCov {
  SE3 T;
  Mat6 covariance = Mat6::Zero();
};

/// Composition E_0 · E_1 · … · E_{n-1} of consecutive edges with first-order
/// propagation of their (independent) covariances:
///   T exp(ξ) = Π E_k exp(ξ_k)  ⇒  ξ = Σ_k Ad(G_k⁻¹) ξ_k,  G_k = E_{k+1}⋯E_{n-1}.
/// An empty chain is the identity with zero covariance.
RelativePoseCov composeEdges(const std::vector<RelativePoseCov>& edges);

/// Covariance of T⁻¹ given that of T (right perturbations): Ad_T Σ Ad_Tᵀ.
Mat6 invertedCovariance(const SE3& T, const Mat6& covariance);

/// Symmetric inverse of a covariance / information (LDLT); an error when it is
/// not positive definite or not finite.
Expected<Mat6> invertSpd(const Mat6& m);

}  // namespace hermes
