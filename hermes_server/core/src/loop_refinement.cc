#include "loop_refinement.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>

#include <ceres/ceres.h>
#include <Eigen/Eigenvalues>

namespace hermes {
namespace server {
namespace detail {

namespace {

template <typename T>
using V3 = Eigen::Matrix<T, 3, 1>;

/// Pixel residual of a point in a camera frame against the observed bearing.
struct Pixel {
  static constexpr int kDim = 2;
  Pixel(const Vec3& bearing, double focal) : obs(bearing.head<2>() / bearing.z()), f(focal) {}
  template <typename T>
  bool operator()(const V3<T>& pc, T* r) const {
    if (pc.z() <= T(1e-9)) return false;
    r[0] = T(f) * (pc.x() / pc.z() - T(obs.x()));
    r[1] = T(f) * (pc.y() / pc.z() - T(obs.y()));
    return true;
  }
  Vec2 obs;
  double f;
};

/// Inverse-depth residual against a keypoint's measured depth, in disparity
/// pixels: fb * (1/z_pred - 1/z_obs).
struct InverseDepth {
  static constexpr int kDim = 1;
  InverseDepth(double depth, double focal_baseline) : inv_z(1.0 / depth), fb(focal_baseline) {}
  template <typename T>
  bool operator()(const V3<T>& pc, T* r) const {
    if (pc.z() <= T(1e-9)) return false;
    r[0] = T(fb) * (T(1) / pc.z() - T(inv_z));
    return true;
  }
  double inv_z;
  double fb;
};

/// A measurement `Model` of a point (query reference frame) by a query camera.
template <typename Model>
struct InQuery {
  InQuery(const SE3& T_refQ_C, Model model) : T_C_ref(T_refQ_C.inverse()), m(model) {}
  template <typename T>
  bool operator()(const T* p, T* r) const {
    const V3<T> P(p[0], p[1], p[2]);
    return m(V3<T>(T_C_ref.rotation().cast<T>() * P + T_C_ref.translation().cast<T>()), r);
  }
  ceres::CostFunction* cost() const {
    return new ceres::AutoDiffCostFunction<InQuery, Model::kDim, 3>(new InQuery(*this));
  }
  SE3 T_C_ref;
  Model m;
};

/// The same by a candidate camera; depends on the pose T_refQ_refC = (q [x y z w], t).
template <typename Model>
struct InCandidate {
  InCandidate(const SE3& T_refC_C, Model model) : T_C_ref(T_refC_C.inverse()), m(model) {}
  template <typename T>
  bool operator()(const T* q, const T* t, const T* p, T* r) const {
    const Eigen::Quaternion<T> Q(q[3], q[0], q[1], q[2]);
    const V3<T> p_refC = Q.conjugate() * (V3<T>(p[0], p[1], p[2]) - V3<T>(t[0], t[1], t[2]));
    return m(V3<T>(T_C_ref.rotation().cast<T>() * p_refC + T_C_ref.translation().cast<T>()), r);
  }
  ceres::CostFunction* cost() const {
    return new ceres::AutoDiffCostFunction<InCandidate, Model::kDim, 4, 3, 3>(new InCandidate(*this));
  }
  SE3 T_C_ref;
  Model m;
};

/// The residual terms of one correspondence; depth terms only where measured.
struct Terms {
  InQuery<Pixel> rq;
  InCandidate<Pixel> rc;
  std::optional<InQuery<InverseDepth>> dq;
  std::optional<InCandidate<InverseDepth>> dc;
};

/// Midpoint triangulation in the query reference frame; false when parallel or
/// behind a camera.
bool triangulate(const GeneralizedCorrespondences& corr, int i, const SE3& T, Vec3* p) {
  const SE3& Tq = corr.T_refQ_Cq[corr.cam_q[i]];
  const SE3 Tc = T * corr.T_refC_Cc[corr.cam_c[i]];
  // A measured depth fixes the point better than a short-baseline intersection;
  // the point must lie in front of both cameras (else the match is an outlier
  // and would make every residual evaluation of the refinement fail).
  auto inFront = [&](const Vec3& x) {
    return (Tq.inverse() * x).z() > 1e-6 && (Tc.inverse() * x).z() > 1e-6;
  };
  if (corr.depthQ(i) > 0) {
    const Vec3& b = corr.bearings_q[i];
    if (b.z() <= 1e-9) return false;
    *p = Tq * (b * (corr.depthQ(i) / b.z()));
    return inFront(*p);
  }
  if (corr.depthC(i) > 0) {
    const Vec3& b = corr.bearings_c[i];
    if (b.z() <= 1e-9) return false;
    *p = Tc * (b * (corr.depthC(i) / b.z()));
    return inFront(*p);
  }
  const Vec3 c1 = Tq.translation(), d1 = Tq.quat() * corr.bearings_q[i];
  const Vec3 c2 = Tc.translation(), d2 = Tc.quat() * corr.bearings_c[i];
  const Vec3 w = c1 - c2;
  const double b = d1.dot(d2), d = d1.dot(w), e = d2.dot(w);
  const double denom = 1.0 - b * b;
  if (denom < 1e-10) return false;
  const double l1 = (b * e - d) / denom, l2 = (e - b * d) / denom;
  if (l1 <= 0 || l2 <= 0) return false;
  *p = 0.5 * ((c1 + l1 * d1) + (c2 + l2 * d2));
  return true;
}

/// Pixel and disparity residuals of one correspondence (6 values; depth rows
/// are 0 where no depth was measured).
Vec6 residuals(const Terms& c, const SE3& T, const Vec3& p) {
  Vec6 r = Vec6::Zero();
  r.head<4>().setConstant(1e6);
  const Eigen::Vector4d qc = T.quat().coeffs();  // x y z w
  c.rq(p.data(), r.data());
  c.rc(qc.data(), T.translation().data(), p.data(), r.data() + 2);
  if (c.dq && !(*c.dq)(p.data(), r.data() + 4)) r(4) = 1e6;
  if (c.dc && !(*c.dc)(qc.data(), T.translation().data(), p.data(), r.data() + 5)) r(5) = 1e6;
  return r;
}

/// A few Gauss-Newton steps on one point with the pose held (numeric
/// Jacobian); left where it was when a residual is invalid or a step fails.
void refinePoint(const Terms& c, const SE3& T, Vec3* p) {
  const double h = 1e-6;
  for (int it = 0; it < 3; ++it) {
    const Vec6 r = residuals(c, T, *p);
    if (!(r.cwiseAbs().maxCoeff() < 1e5)) return;
    Eigen::Matrix<double, 6, 3> J;
    for (int j = 0; j < 3; ++j) {
      Vec3 d = Vec3::Zero();
      d(j) = h;
      J.col(j) = (residuals(c, T, *p + d) - residuals(c, T, *p - d)) / (2 * h);
    }
    const Mat3 H = J.transpose() * J;
    const Vec3 step = H.ldlt().solve(-J.transpose() * r);
    if (!step.allFinite()) return;
    const Vec3 next = *p + step;
    if (!(residuals(c, T, next).squaredNorm() < r.squaredNorm())) return;
    *p = next;
    if (step.norm() < 1e-9 * (1 + p->norm())) return;
  }
}

/// Robust cost of the pose-dependent residuals (candidate pixel and depth
/// rows) of every point at pose T, Huber as in the bundle adjustment.
double poseCost(const std::vector<Terms>& terms, const std::vector<Vec3>& points, const SE3& T, double huber) {
  auto rho = [huber](double s) { return s <= huber * huber ? s : 2 * huber * std::sqrt(s) - huber * huber; };
  double cost = 0;
  for (std::size_t k = 0; k < terms.size(); ++k) {
    const Vec6 r = residuals(terms[k], T, points[k]);
    if (!(r.cwiseAbs().maxCoeff() < 1e5)) continue;
    cost += rho(r.segment<2>(2).squaredNorm()) + rho(r(5) * r(5));
  }
  return cost;
}

/// Gauss-Newton steps on the pose alone over every point (held; numeric
/// Jacobian, Huber weights): the pose of a bundle adjustment that saw a
/// subset, brought to all the inliers.
SE3 refinePose(const std::vector<Terms>& terms, const std::vector<Vec3>& points, SE3 T, double huber) {
  const double h = 1e-6;
  double cost = poseCost(terms, points, T, huber);
  for (int it = 0; it < 3; ++it) {
    Mat6 H = Mat6::Zero();
    Vec6 g = Vec6::Zero();
    for (std::size_t k = 0; k < terms.size(); ++k) {
      const Vec6 r = residuals(terms[k], T, points[k]);
      if (!(r.cwiseAbs().maxCoeff() < 1e5)) continue;
      Eigen::Matrix<double, 6, 6> J;
      for (int j = 0; j < 6; ++j) {
        Vec6 xi = Vec6::Zero();
        xi(j) = h;
        J.col(j) = (residuals(terms[k], T * SE3::exp(xi), points[k]) -
                    residuals(terms[k], T * SE3::exp(-xi), points[k])) / (2 * h);
      }
      Vec6 w = Vec6::Zero();  // rows that depend on the pose, Huber-weighted per block
      const double nc = r.segment<2>(2).norm(), nd = std::abs(r(5));
      w(2) = w(3) = nc <= huber ? 1.0 : huber / nc;
      w(5) = nd <= huber ? 1.0 : huber / nd;
      H += J.transpose() * w.asDiagonal() * J;
      g += J.transpose() * w.asDiagonal() * r;
    }
    const Vec6 step = H.ldlt().solve(-g);
    if (!step.allFinite()) break;
    const SE3 next = T * SE3::exp(step);
    const double c = poseCost(terms, points, next, huber);
    if (!(c < cost)) break;
    T = next;
    cost = c;
    if (step.norm() < 1e-10) break;
  }
  return T;
}

Terms makeTerms(const GeneralizedCorrespondences& corr, int i, double fb) {
  const SE3& Tq = corr.T_refQ_Cq[corr.cam_q[i]];
  const SE3& Tc = corr.T_refC_Cc[corr.cam_c[i]];
  Terms c{InQuery<Pixel>(Tq, Pixel(corr.bearings_q[i], corr.focal_px)),
          InCandidate<Pixel>(Tc, Pixel(corr.bearings_c[i], corr.focal_px)), std::nullopt, std::nullopt};
  if (fb > 0 && corr.depthQ(i) > 0) c.dq.emplace(Tq, InverseDepth(corr.depthQ(i), fb));
  if (fb > 0 && corr.depthC(i) > 0) c.dc.emplace(Tc, InverseDepth(corr.depthC(i), fb));
  return c;
}

/// One point's contribution to the pose information (unit pixel noise): the
/// Schur complement of the point in its 6+3 Gauss-Newton Hessian (numeric
/// Jacobian). False when the point is not constrained in 3D.
bool pointInformation(const Terms& c, const SE3& T, const Vec3& p, Mat6* info) {
  const double h = 1e-6;
  Eigen::Matrix<double, 6, 9> J;
  for (int j = 0; j < 9; ++j) {
    Vec6 xi = Vec6::Zero();
    Vec3 dp = Vec3::Zero();
    if (j < 6) xi(j) = h; else dp(j - 6) = h;
    J.col(j) = (residuals(c, T * SE3::exp(xi), p + dp) - residuals(c, T * SE3::exp(-xi), p - dp)) / (2 * h);
  }
  const Eigen::Matrix<double, 6, 6> Jx = J.leftCols<6>();
  const Eigen::Matrix<double, 6, 3> Jp = J.rightCols<3>();
  const Mat3 Hpp = Jp.transpose() * Jp;
  Eigen::SelfAdjointEigenSolver<Mat3> ep(Hpp);
  if (!(ep.eigenvalues()(0) > 1e-9 * ep.eigenvalues()(2))) return false;
  const Eigen::Matrix<double, 3, 6> Hpx = Jp.transpose() * Jx;
  *info += Jx.transpose() * Jx - Hpx.transpose() * Hpp.inverse() * Hpx;
  return true;
}

/// Largest translation standard deviation [m] of an information matrix
/// (infinite when it is not positive definite).
double translationSigma(const Mat6& info, Mat6* covariance = nullptr) {
  Eigen::SelfAdjointEigenSolver<Mat6> eig(0.5 * (info + info.transpose()));
  if (!(eig.eigenvalues().minCoeff() > 1e-9 * eig.eigenvalues().maxCoeff()) ||
      !(eig.eigenvalues().minCoeff() > 0)) {
    return std::numeric_limits<double>::infinity();
  }
  const Mat6 cov = eig.eigenvectors() * eig.eigenvalues().cwiseInverse().asDiagonal() *
                   eig.eigenvectors().transpose();
  if (covariance) *covariance = cov;
  Eigen::SelfAdjointEigenSolver<Mat3> et(cov.topLeftCorner<3, 3>());
  return std::sqrt(std::max(0.0, et.eigenvalues().maxCoeff()));
}

}  // namespace

double translationSigmaBound(const GeneralizedCorrespondences& corr, const std::vector<int>& inliers,
                             const SE3& T, const LoopClosureParams& params, int max_points) {
  const std::size_t n = inliers.size();
  const std::size_t m = std::min<std::size_t>(n, static_cast<std::size_t>(std::max(1, max_points)));
  Mat6 info = Mat6::Zero();
  for (std::size_t j = 0; j < m; ++j) {
    const int i = inliers[j * n / m];
    Vec3 p;
    if (triangulate(corr, i, T, &p)) pointInformation(makeTerms(corr, i, params.depth_focal_baseline_px_m), T, p, &info);
  }
  const double floor = params.sigma_floor_px;
  info *= static_cast<double>(n) / m / (floor * floor * params.covariance_inflation);
  return translationSigma(info);
}

Refinement refineGeneralizedPose(const GeneralizedCorrespondences& corr,
                                 const std::vector<int>& inliers, const SE3& T0,
                                 const LoopClosureParams& params) {
  Refinement out;
  std::vector<int> ids;
  std::vector<Vec3> points;
  for (int i : inliers) {
    Vec3 p;
    if (triangulate(corr, i, T0, &p)) {
      ids.push_back(i);
      points.push_back(p);
    }
  }
  Eigen::Vector4d q = T0.quat().coeffs();
  Vec3 t = T0.translation();
  std::vector<Terms> terms;
  for (int i : ids) terms.push_back(makeTerms(corr, i, params.depth_focal_baseline_px_m));

  // The bundle adjustment sees an evenly spaced subset of at most
  // refine_max_points inliers (its cost grows with the points; a rig pair
  // holds ~1000); the others are triangulated again at its pose below.
  std::vector<bool> in_ba(ids.size(), true);
  const std::size_t cap = params.refine_max_points > 0 ? static_cast<std::size_t>(params.refine_max_points) : ids.size();
  if (ids.size() > cap) {
    in_ba.assign(ids.size(), false);
    for (std::size_t j = 0; j < cap; ++j) in_ba[j * ids.size() / cap] = true;
  }
  bool refined = false;
  if (params.refine && ids.size() >= 18) {
    ceres::Problem::Options popt;
    popt.manifold_ownership = ceres::TAKE_OWNERSHIP;
    ceres::Problem problem(popt);
    problem.AddParameterBlock(q.data(), 4, new ceres::EigenQuaternionManifold());
    problem.AddParameterBlock(t.data(), 3);
    const double huber = params.ransac_threshold_px;
    for (std::size_t k = 0; k < ids.size(); ++k) {
      if (!in_ba[k]) continue;
      const Terms& c = terms[k];
      double* pk = points[k].data();
      problem.AddResidualBlock(c.rq.cost(), new ceres::HuberLoss(huber), pk);
      problem.AddResidualBlock(c.rc.cost(), new ceres::HuberLoss(huber), q.data(), t.data(), pk);
      if (c.dq) problem.AddResidualBlock(c.dq->cost(), new ceres::HuberLoss(huber), pk);
      if (c.dc)
        problem.AddResidualBlock(c.dc->cost(), new ceres::HuberLoss(huber), q.data(), t.data(), pk);
    }
    ceres::Solver::Options opt;
    opt.linear_solver_type = ceres::DENSE_SCHUR;
    opt.max_num_iterations = 20;
    opt.num_threads = 1;
    opt.logging_type = ceres::SILENT;
    ceres::Solver::Summary summary;
    ceres::Solve(opt, &problem, &summary);
    out.iterations = static_cast<int>(summary.iterations.size());
    if (!summary.IsSolutionUsable() || !q.allFinite() || !t.allFinite()) {
      q = T0.quat().coeffs();
      t = T0.translation();
      for (std::size_t k = 0; k < ids.size(); ++k) triangulate(corr, ids[k], T0, &points[k]);
    } else {
      refined = true;
    }
  }
  SE3 T(Quat(q(3), q(0), q(1), q(2)), t);
  if (refined && ids.size() > cap) {
    // The points left out of the bundle adjustment, best given its pose; then
    // the pose given every point, and every point given that pose.
    for (std::size_t k = 0; k < ids.size(); ++k)
      if (!in_ba[k] && triangulate(corr, ids[k], T, &points[k])) refinePoint(terms[k], T, &points[k]);
    T = refinePose(terms, points, T, params.ransac_threshold_px);
    for (std::size_t k = 0; k < ids.size(); ++k) refinePoint(terms[k], T, &points[k]);
  }
  out.T_refQ_refC = T;

  // Inliers by reprojection error in both views; information by Schur complement.
  Mat6 info = Mat6::Zero();
  double sq_sum = 0;
  int num_residuals = 0;
  for (std::size_t k = 0; k < ids.size(); ++k) {
    const Vec6 r = residuals(terms[k], T, points[k]);
    // A measured depth that disagrees makes the match an outlier (metric check).
    const double th = params.ransac_threshold_px;
    if (!(r.head<2>().norm() < th && r.segment<2>(2).norm() < th && std::abs(r(4)) < th &&
          std::abs(r(5)) < th)) {
      continue;
    }
    if (!pointInformation(terms[k], T, points[k], &info)) continue;
    sq_sum += r.squaredNorm();
    num_residuals += 4 + (terms[k].dq ? 1 : 0) + (terms[k].dc ? 1 : 0);
    out.inliers.push_back(ids[k]);
    if (terms[k].dq || terms[k].dc) ++out.depth_inliers;
  }
  const int n = static_cast<int>(out.inliers.size());
  if (n < 7) {
    out.reason = "only " + std::to_string(n) + " well-triangulated inliers";
    return out;
  }
  // Degrees of freedom: the residuals less 3 point parameters per inlier and 6
  // pose parameters (4n - 3n - 6 = n - 6 without depths).
  const int dof = std::max(1, num_residuals - 3 * n - 6);
  const double sigma = std::max(std::sqrt(sq_sum / dof), params.sigma_floor_px);
  out.sigma_px = sigma;
  info /= sigma * sigma * params.covariance_inflation;
  info = 0.5 * (info + info.transpose()).eval();
  const double sigma_t = translationSigma(info, &out.covariance);
  if (!std::isfinite(sigma_t)) {
    out.reason = "information is rank deficient (degenerate rig geometry)";
    return out;
  }
  out.information = info;
  if (sigma_t > params.max_translation_sigma_m) {
    out.reason = "translation poorly constrained (sigma " + std::to_string(sigma_t) + " m > " +
                 std::to_string(params.max_translation_sigma_m) + " m)";
    return out;
  }
  out.ok = true;
  return out;
}

}  // namespace detail
}  // namespace server
}  // namespace hermes
