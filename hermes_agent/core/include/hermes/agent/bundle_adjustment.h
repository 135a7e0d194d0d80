// Windowed bundle adjustment (DESIGN.md §3, local mapping): keyframe poses
// T_C_W (quaternion + translation) and landmark positions p_W refined jointly
// by Ceres on the Huber-robustified reprojection error. Stereo / depth
// observations add a third residual, the right-image u coordinate
// u_r = u - fx·b/z (a depth measurement is turned into a virtual right u with
// the same baseline, so depth noise is weighted in disparity like stereo).
#pragma once

#include <vector>

#include "hermes/core/config.h"
#include "hermes/core/geometry.h"
#include "hermes/core/map_types.h"
#include "hermes/core/status.h"

namespace hermes {

struct BundleAdjustmentParams {
  int max_iterations = 10;       ///< Levenberg-Marquardt iterations
  double huber_px = 2.45;        ///< Huber threshold on the whitened residual (sqrt(chi2_2, 95%))
  double outlier_chi2 = 7.815;   ///< whitened squared error above this = outlier (chi2_3, 95%)
  double min_depth = 0.05;       ///< observations behind this depth are outliers [m]

  /// Keys under `section` (e.g. "ba").
  Status read(const Config& config, const std::string& section = "ba");
  void write(ConfigWriter* writer, const std::string& section = "ba") const;
  Status validate() const;
};

/// One measurement of landmark `point` in keyframe `pose`.
struct BaObservation {
  int pose = 0;
  int point = 0;
  Vec2 uv = Vec2::Zero();  ///< left image pixel [px]
  double u_right = -1;     ///< right image u [px]; < 0 = monocular
  double sigma_px = 1;     ///< pixel standard deviation (pyramid scale)
};

struct BaProblem {
  PinholeIntrinsics K;
  double baseline = 0;               ///< [m], used for the u_right residuals
  std::vector<SE3> T_C_W;            ///< poses (camera <- world)
  std::vector<bool> pose_fixed;      ///< per pose; at least one must be fixed
  std::vector<Vec3> p_W;             ///< landmark positions
  std::vector<BaObservation> observations;
};

struct BaSummary {
  double initial_cost = 0, final_cost = 0;  ///< Ceres cost (robustified, ½Σρ)
  int iterations = 0;
  double time_ms = 0;
  std::vector<bool> outlier;  ///< per observation after the solve
  int num_outliers = 0;
};

/// Solves in place. Errors: indices out of range, no fixed pose, non-finite input,
/// stereo residuals without a positive baseline.
Expected<BaSummary> solveBundleAdjustment(BaProblem* problem, const BundleAdjustmentParams& p);

/// Templated residual functors (exposed for the Jacobian tests). Parameters:
/// q_C_W (Eigen order x y z w), t_C_W, p_W; residuals whitened by 1/sigma.
struct MonoReprojectionError {
  MonoReprojectionError(const PinholeIntrinsics& K, const Vec2& uv, double sigma)
      : fx(K.fx), fy(K.fy), cx(K.cx), cy(K.cy), u(uv.x()), v(uv.y()), inv_sigma(1.0 / sigma) {}
  template <typename T>
  bool operator()(const T* q, const T* t, const T* p, T* r) const {
    T pc[3];
    rotate(q, t, p, pc);
    r[0] = (T(fx) * pc[0] / pc[2] + T(cx) - T(u)) * T(inv_sigma);
    r[1] = (T(fy) * pc[1] / pc[2] + T(cy) - T(v)) * T(inv_sigma);
    return true;
  }
  /// p_C = R(q)·p + t with a unit quaternion q = (x, y, z, w).
  template <typename T>
  static void rotate(const T* q, const T* t, const T* p, T* out) {
    const T x = q[0], y = q[1], z = q[2], w = q[3];
    // v' = v + 2w (u × v) + 2 u × (u × v), u = (x, y, z)
    const T c0 = y * p[2] - z * p[1], c1 = z * p[0] - x * p[2], c2 = x * p[1] - y * p[0];
    const T d0 = y * c2 - z * c1, d1 = z * c0 - x * c2, d2 = x * c1 - y * c0;
    out[0] = p[0] + T(2) * (w * c0 + d0) + t[0];
    out[1] = p[1] + T(2) * (w * c1 + d1) + t[1];
    out[2] = p[2] + T(2) * (w * c2 + d2) + t[2];
  }
  double fx, fy, cx, cy, u, v, inv_sigma;
};

struct StereoReprojectionError {
  StereoReprojectionError(const PinholeIntrinsics& K, double baseline, const Vec2& uv,
                          double u_right, double sigma)
      : mono(K, uv, sigma), bf(K.fx * baseline), ur(u_right) {}
  template <typename T>
  bool operator()(const T* q, const T* t, const T* p, T* r) const {
    T pc[3];
    MonoReprojectionError::rotate(q, t, p, pc);
    const T u = T(mono.fx) * pc[0] / pc[2] + T(mono.cx);
    r[0] = (u - T(mono.u)) * T(mono.inv_sigma);
    r[1] = (T(mono.fy) * pc[1] / pc[2] + T(mono.cy) - T(mono.v)) * T(mono.inv_sigma);
    r[2] = (u - T(bf) / pc[2] - T(ur)) * T(mono.inv_sigma);
    return true;
  }
  MonoReprojectionError mono;
  double bf, ur;
};

}  // namespace hermes
