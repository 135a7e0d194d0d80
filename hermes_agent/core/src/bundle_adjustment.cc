#include "hermes/agent/bundle_adjustment.h"

#include <chrono>
#include <memory>

#include <ceres/ceres.h>

namespace hermes {

Status BundleAdjustmentParams::read(const Config& c, const std::string& s) {
  Status st = c.get(s + ".max_iterations", &max_iterations);
  if (!st) return st;
  for (auto [key, ptr] : {std::pair<const char*, double*>{"huber_px", &huber_px},
                          {"outlier_chi2", &outlier_chi2},
                          {"min_depth", &min_depth}}) {
    st = c.get(s + "." + key, ptr);
    if (!st) return st;
  }
  return validate();
}

void BundleAdjustmentParams::write(ConfigWriter* w, const std::string& s) const {
  w->set(s + ".max_iterations", max_iterations);
  w->set(s + ".huber_px", huber_px);
  w->set(s + ".outlier_chi2", outlier_chi2);
  w->set(s + ".min_depth", min_depth);
}

Status BundleAdjustmentParams::validate() const {
  if (max_iterations < 1) return Error{"ba.max_iterations must be >= 1"};
  if (!(huber_px > 0)) return Error{"ba.huber_px must be > 0"};
  if (!(outlier_chi2 > 0)) return Error{"ba.outlier_chi2 must be > 0"};
  if (!(min_depth > 0)) return Error{"ba.min_depth must be > 0"};
  return Status::Ok();
}

namespace {

/// Whitened squared error and camera-frame depth of one observation.
double squaredError(const BaProblem& pb, const BaObservation& o, double* depth) {
  const SE3& T = pb.T_C_W[o.pose];
  const Vec3 pc = T * pb.p_W[o.point];
  *depth = pc.z();
  if (pc.z() <= 0) return 1e30;
  const Vec2 uv = pb.K.project(pc);
  double e2 = (uv - o.uv).squaredNorm();
  if (o.u_right >= 0) {
    const double ur = uv.x() - pb.K.fx * pb.baseline / pc.z();
    e2 += (ur - o.u_right) * (ur - o.u_right);
  }
  return e2 / (o.sigma_px * o.sigma_px);
}

}  // namespace

Expected<BaSummary> solveBundleAdjustment(BaProblem* pb, const BundleAdjustmentParams& params) {
  Status vs = params.validate();
  if (!vs) return Error{vs.error()};
  const auto t0 = std::chrono::steady_clock::now();
  const int np = int(pb->T_C_W.size()), nl = int(pb->p_W.size());
  if (int(pb->pose_fixed.size()) != np)
    return Error{"bundle adjustment: pose_fixed has " + std::to_string(pb->pose_fixed.size()) +
                 " entries for " + std::to_string(np) + " poses"};
  bool any_fixed = false;
  for (int i = 0; i < np; ++i) {
    any_fixed = any_fixed || pb->pose_fixed[i];
    if (!pb->T_C_W[i].translation().allFinite() || !pb->T_C_W[i].quat().coeffs().allFinite())
      return Error{"bundle adjustment: pose " + std::to_string(i) + " is not finite"};
  }
  if (!any_fixed) return Error{"bundle adjustment: no fixed pose (gauge undefined)"};
  for (int i = 0; i < nl; ++i)
    if (!pb->p_W[i].allFinite())
      return Error{"bundle adjustment: point " + std::to_string(i) + " is not finite"};

  std::vector<std::array<double, 4>> q(np);
  std::vector<std::array<double, 3>> t(np), p(nl);
  for (int i = 0; i < np; ++i) {
    const auto& c = pb->T_C_W[i].quat().coeffs();
    q[i] = {c.x(), c.y(), c.z(), c.w()};
    const Vec3& tr = pb->T_C_W[i].translation();
    t[i] = {tr.x(), tr.y(), tr.z()};
  }
  for (int i = 0; i < nl; ++i) p[i] = {pb->p_W[i].x(), pb->p_W[i].y(), pb->p_W[i].z()};

  ceres::Problem::Options po;
  po.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(po);
  ceres::EigenQuaternionManifold quat_manifold;
  std::vector<bool> pose_used(np, false);
  for (std::size_t k = 0; k < pb->observations.size(); ++k) {
    const BaObservation& o = pb->observations[k];
    if (o.pose < 0 || o.pose >= np || o.point < 0 || o.point >= nl)
      return Error{"bundle adjustment: observation " + std::to_string(k) +
                   " indexes pose " + std::to_string(o.pose) + " / point " +
                   std::to_string(o.point) + " out of range"};
    if (!(o.sigma_px > 0) || !o.uv.allFinite())
      return Error{"bundle adjustment: observation " + std::to_string(k) +
                   " has a bad pixel or sigma"};
    ceres::CostFunction* cost;
    if (o.u_right >= 0) {
      if (!(pb->baseline > 0))
        return Error{"bundle adjustment: stereo observation but baseline <= 0"};
      cost = new ceres::AutoDiffCostFunction<StereoReprojectionError, 3, 4, 3, 3>(
          new StereoReprojectionError(pb->K, pb->baseline, o.uv, o.u_right, o.sigma_px));
    } else {
      cost = new ceres::AutoDiffCostFunction<MonoReprojectionError, 2, 4, 3, 3>(
          new MonoReprojectionError(pb->K, o.uv, o.sigma_px));
    }
    problem.AddResidualBlock(cost, new ceres::HuberLoss(params.huber_px), q[o.pose].data(),
                             t[o.pose].data(), p[o.point].data());
    if (!pose_used[o.pose]) {
      pose_used[o.pose] = true;
      problem.SetManifold(q[o.pose].data(), &quat_manifold);
      if (pb->pose_fixed[o.pose]) {
        problem.SetParameterBlockConstant(q[o.pose].data());
        problem.SetParameterBlockConstant(t[o.pose].data());
      }
    }
  }

  BaSummary out;
  if (!pb->observations.empty()) {
    ceres::Solver::Options so;
    so.linear_solver_type = ceres::SPARSE_SCHUR;
    so.max_num_iterations = params.max_iterations;
    so.num_threads = 1;
    so.logging_type = ceres::SILENT;
    ceres::Solver::Summary summary;
    ceres::Solve(so, &problem, &summary);
    out.initial_cost = summary.initial_cost;
    out.final_cost = summary.final_cost;
    out.iterations = int(summary.iterations.size());
    for (int i = 0; i < np; ++i) {
      if (pb->pose_fixed[i] || !pose_used[i]) continue;
      pb->T_C_W[i] = SE3(Quat(q[i][3], q[i][0], q[i][1], q[i][2]), Vec3(t[i][0], t[i][1], t[i][2]));
    }
    for (int i = 0; i < nl; ++i) pb->p_W[i] = Vec3(p[i][0], p[i][1], p[i][2]);
  }
  out.outlier.assign(pb->observations.size(), false);
  for (std::size_t k = 0; k < pb->observations.size(); ++k) {
    double depth = 0;
    const double e2 = squaredError(*pb, pb->observations[k], &depth);
    const double thr = pb->observations[k].u_right >= 0 ? params.outlier_chi2
                                                        : params.outlier_chi2 * 5.991 / 7.815;
    if (e2 > thr || depth < params.min_depth) {
      out.outlier[k] = true;
      ++out.num_outliers;
    }
  }
  out.time_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  return out;
}

}  // namespace hermes
