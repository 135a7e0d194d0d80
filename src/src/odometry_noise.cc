#include "hermes/core/odometry_noise.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Cholesky>

namespace hermes {

Status OdometryNoiseParams::read(const Config& c) {
  struct Key { const char* name; double* v; };
  for (Key k : {Key{"trans_floor_m", &trans_floor_m}, Key{"trans_per_sqrt_m", &trans_per_sqrt_m},
                Key{"trans_per_sqrt_rad", &trans_per_sqrt_rad}, Key{"rot_floor_rad", &rot_floor_rad},
                Key{"rot_per_sqrt_m", &rot_per_sqrt_m}, Key{"rot_per_sqrt_rad", &rot_per_sqrt_rad},
                Key{"min_weight", &min_weight}, Key{"lost_inflation", &lost_inflation}})
    if (Status s = c.get(std::string("odometry.") + k.name, k.v); !s) return s;
  if (Status s = c.get("odometry.shared_ref", &shared_ref); !s) return s;
  if (Status s = validate(); !s) return Error{"odometry: " + s.error()};
  return Status::Ok();
}

void OdometryNoiseParams::write(ConfigWriter* w) const {
  w->set("odometry.trans_floor_m", trans_floor_m);
  w->set("odometry.trans_per_sqrt_m", trans_per_sqrt_m);
  w->set("odometry.trans_per_sqrt_rad", trans_per_sqrt_rad);
  w->set("odometry.rot_floor_rad", rot_floor_rad);
  w->set("odometry.rot_per_sqrt_m", rot_per_sqrt_m);
  w->set("odometry.rot_per_sqrt_rad", rot_per_sqrt_rad);
  w->set("odometry.shared_ref", shared_ref);
  w->set("odometry.min_weight", min_weight);
  w->set("odometry.lost_inflation", lost_inflation);
}

Status OdometryNoiseParams::validate() const {
  if (!(trans_floor_m > 0) || !(rot_floor_rad > 0))
    return Error{"trans_floor_m and rot_floor_rad must be > 0"};
  for (double v : {trans_per_sqrt_m, trans_per_sqrt_rad, rot_per_sqrt_m, rot_per_sqrt_rad})
    if (!(v >= 0) || !std::isfinite(v)) return Error{"the per-metre / per-radian sigmas must be >= 0"};
  if (shared_ref < 1) return Error{"shared_ref must be >= 1"};
  if (!(min_weight > 0 && min_weight <= 1)) return Error{"min_weight must be in (0, 1]"};
  if (!(lost_inflation >= 1) || !std::isfinite(lost_inflation))
    return Error{"lost_inflation must be >= 1"};
  return Status::Ok();
}

Mat6 odometryCovariance(const SE3& T_a_b, int shared, bool lost, const OdometryNoiseParams& p) {
  const double d = T_a_b.translation().norm();
  const double th = rotationAngle(T_a_b.rotation());
  auto sq = [](double v) { return v * v; };
  const double var_t = sq(p.trans_floor_m) + sq(p.trans_per_sqrt_m) * d + sq(p.trans_per_sqrt_rad) * th;
  const double var_r = sq(p.rot_floor_rad) + sq(p.rot_per_sqrt_m) * d + sq(p.rot_per_sqrt_rad) * th;
  double scale = 1.0;
  if (shared >= 0) scale /= std::clamp(double(shared) / p.shared_ref, p.min_weight, 1.0);
  if (lost) scale *= p.lost_inflation;
  Vec6 diag;
  diag << Vec3::Constant(var_t * scale), Vec3::Constant(var_r * scale);
  return Mat6(diag.asDiagonal());
}

Mat6 odometryInformation(const SE3& T_a_b, int shared, bool lost, const OdometryNoiseParams& p) {
  const Vec6 var = odometryCovariance(T_a_b, shared, lost, p).diagonal();
  return Mat6(var.cwiseInverse().asDiagonal());
}

RelativePoseCov composeEdges(const std::vector<RelativePoseCov>& edges) {
  RelativePoseCov out;
  SE3 G;  // product of the edges after the current one
  for (auto it = edges.rbegin(); it != edges.rend(); ++it) {
    const Mat6 A = G.inverse().adjoint();
    out.covariance += A * it->covariance * A.transpose();
    G = it->T * G;
  }
  out.T = G;
  return out;
}

Mat6 invertedCovariance(const SE3& T, const Mat6& covariance) {
  const Mat6 Ad = T.adjoint();  // (T exp(x))^-1 = T^-1 exp(-Ad_T x)
  return Ad * covariance * Ad.transpose();
}

Expected<Mat6> invertSpd(const Mat6& m) {
  if (!m.allFinite()) return Error{"matrix is not finite"};
  Eigen::LDLT<Mat6> ldlt(0.5 * (m + m.transpose()));
  if (ldlt.info() != Eigen::Success || !ldlt.isPositive() ||
      (ldlt.vectorD().array() <= 0).any())
    return Error{"matrix is not positive definite"};
  Mat6 inv = ldlt.solve(Mat6::Identity());
  return Mat6(0.5 * (inv + inv.transpose()));
}

}  // namespace hermes
