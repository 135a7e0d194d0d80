#include "hermes/core/alignment.h"

#include <Eigen/SVD>
#include <cmath>

namespace hermes {
namespace eval {

const char* toString(AlignMode mode) {
  switch (mode) {
    case AlignMode::kNone: return "none";
    case AlignMode::kFirstPose: return "first";
    case AlignMode::kSE3: return "se3";
    case AlignMode::kSim3: return "sim3";
  }
  return "?";
}

Expected<AlignMode> parseAlignMode(const std::string& name) {
  for (AlignMode m : {AlignMode::kNone, AlignMode::kFirstPose, AlignMode::kSE3, AlignMode::kSim3})
    if (name == toString(m)) return m;
  return Error{"unknown alignment '" + name + "' (valid: se3, sim3, first, none)"};
}

Expected<Alignment> umeyama(const std::vector<Vec3>& src, const std::vector<Vec3>& dst,
                            bool with_scale) {
  if (src.size() != dst.size())
    return Error{"umeyama: " + std::to_string(src.size()) + " source but " +
                 std::to_string(dst.size()) + " target points"};
  const size_t n = src.size();
  if (n < 3) return Error{"umeyama: needs at least 3 matched points, got " + std::to_string(n)};
  Vec3 mu_src = Vec3::Zero(), mu_dst = Vec3::Zero();
  for (size_t i = 0; i < n; ++i) {
    if (!src[i].allFinite() || !dst[i].allFinite())
      return Error{"umeyama: point " + std::to_string(i) + " is not finite"};
    mu_src += src[i];
    mu_dst += dst[i];
  }
  mu_src /= double(n);
  mu_dst /= double(n);
  Mat3 cov = Mat3::Zero();  // (1/n) sum (dst - mu_dst)(src - mu_src)^T
  double var_src = 0;       // (1/n) sum ||src - mu_src||^2
  for (size_t i = 0; i < n; ++i) {
    const Vec3 a = src[i] - mu_src;
    cov += (dst[i] - mu_dst) * a.transpose();
    var_src += a.squaredNorm();
  }
  cov /= double(n);
  var_src /= double(n);

  Eigen::JacobiSVD<Mat3> svd(cov, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Mat3& U = svd.matrixU();
  const Mat3& V = svd.matrixV();
  Vec3 s_diag(1, 1, 1);
  if (U.determinant() * V.determinant() < 0) s_diag(2) = -1;  // avoid a reflection
  const Mat3 R = U * s_diag.asDiagonal() * V.transpose();

  Alignment a;
  a.mode = with_scale ? AlignMode::kSim3 : AlignMode::kSE3;
  if (with_scale) {
    if (var_src <= 1e-300)
      return Error{"umeyama: source points are all identical, scale is undetermined"};
    a.scale = svd.singularValues().dot(s_diag) / var_src;
    if (!(a.scale > 0) || !std::isfinite(a.scale))
      return Error{"umeyama: degenerate point sets (scale " + std::to_string(a.scale) + ")"};
  }
  a.T_gt_est = SE3(R, mu_dst - a.scale * R * mu_src);
  return a;
}

Expected<Alignment> alignPoses(const std::vector<SE3>& gt, const std::vector<SE3>& est,
                               AlignMode mode) {
  if (gt.size() != est.size() || gt.empty())
    return Error{"align: needs equally many (>0) gt and estimate poses, got " +
                 std::to_string(gt.size()) + " and " + std::to_string(est.size())};
  Alignment a;
  a.mode = mode;
  switch (mode) {
    case AlignMode::kNone: return a;
    case AlignMode::kFirstPose: a.T_gt_est = gt.front() * est.front().inverse(); return a;
    case AlignMode::kSE3:
    case AlignMode::kSim3: {
      std::vector<Vec3> src, dst;
      src.reserve(est.size());
      dst.reserve(gt.size());
      for (size_t i = 0; i < gt.size(); ++i) {
        src.push_back(est[i].translation());
        dst.push_back(gt[i].translation());
      }
      return umeyama(src, dst, mode == AlignMode::kSim3);
    }
  }
  return Error{"align: unknown mode"};
}

}  // namespace eval
}  // namespace hermes
