#include "hermes/agent/pose_estimation.h"

#include <algorithm>
#include <cmath>

#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

namespace hermes {

Status PoseEstimationParams::read(const Config& c, const std::string& p) {
  for (auto [key, ptr] : {std::pair<const char*, double*>{"ransac_threshold_px", &ransac_threshold_px},
                          {"ransac_confidence", &ransac_confidence},
                          {"huber_px", &huber_px},
                          {"chi2_threshold", &chi2_threshold},
                          {"chi2_threshold_stereo", &chi2_threshold_stereo},
                          {"stereo_sigma_scale", &stereo_sigma_scale}}) {
    Status s = c.get(p + "." + key, ptr);
    if (!s) return s;
  }
  for (auto [key, ptr] : {std::pair<const char*, int*>{"ransac_iterations", &ransac_iterations},
                          {"refine_rounds", &refine_rounds},
                          {"iterations_per_round", &iterations_per_round},
                          {"min_inliers", &min_inliers}}) {
    Status s = c.get(p + "." + key, ptr);
    if (!s) return s;
  }
  Status s = c.get(p + ".stereo_residual", &stereo_residual);
  if (!s) return s;
  return validate();
}

void PoseEstimationParams::write(ConfigWriter* w, const std::string& p) const {
  w->set(p + ".ransac_threshold_px", ransac_threshold_px);
  w->set(p + ".ransac_iterations", ransac_iterations);
  w->set(p + ".ransac_confidence", ransac_confidence);
  w->set(p + ".huber_px", huber_px);
  w->set(p + ".chi2_threshold", chi2_threshold);
  w->set(p + ".chi2_threshold_stereo", chi2_threshold_stereo);
  w->set(p + ".stereo_residual", stereo_residual);
  w->set(p + ".stereo_sigma_scale", stereo_sigma_scale);
  w->set(p + ".refine_rounds", refine_rounds);
  w->set(p + ".iterations_per_round", iterations_per_round);
  w->set(p + ".min_inliers", min_inliers);
}

Status PoseEstimationParams::validate() const {
  if (!(ransac_threshold_px > 0)) return Error{"pose.ransac_threshold_px must be > 0"};
  if (ransac_iterations < 1) return Error{"pose.ransac_iterations must be >= 1"};
  if (!(ransac_confidence > 0 && ransac_confidence < 1))
    return Error{"pose.ransac_confidence must be in (0, 1)"};
  if (!(huber_px > 0)) return Error{"pose.huber_px must be > 0"};
  if (!(chi2_threshold > 0)) return Error{"pose.chi2_threshold must be > 0"};
  if (!(chi2_threshold_stereo > 0)) return Error{"pose.chi2_threshold_stereo must be > 0"};
  if (!(stereo_sigma_scale > 0)) return Error{"pose.stereo_sigma_scale must be > 0"};
  if (refine_rounds < 1) return Error{"pose.refine_rounds must be >= 1"};
  if (iterations_per_round < 1) return Error{"pose.iterations_per_round must be >= 1"};
  if (min_inliers < 4) return Error{"pose.min_inliers must be >= 4"};
  return Status::Ok();
}

namespace {

Status checkInput(const Correspondences& c, const PoseEstimationParams& p) {
  if (c.uv.size() != c.p_W.size() || (!c.sigma_px.empty() && c.sigma_px.size() != c.p_W.size()) ||
      (!c.u_right.empty() && c.u_right.size() != c.p_W.size()))
    return Error{"pose estimation: correspondence arrays differ in length"};
  if (!c.u_right.empty() && !(c.baseline > 0))
    return Error{"pose estimation: right-image columns given but baseline <= 0"};
  if (int(c.size()) < p.min_inliers)
    return Error{"pose estimation: " + std::to_string(c.size()) + " correspondences, need " +
                 std::to_string(p.min_inliers)};
  for (std::size_t i = 0; i < c.size(); ++i)
    if (!c.p_W[i].allFinite() || !c.uv[i].allFinite() ||
        (!c.sigma_px.empty() && !(c.sigma_px[i] > 0)))
      return Error{"pose estimation: correspondence " + std::to_string(i) +
                   " is not finite or has sigma <= 0"};
  return Status::Ok();
}

double sigmaOf(const Correspondences& c, std::size_t i) {
  return c.sigma_px.empty() ? 1.0 : c.sigma_px[i];
}

/// Whether observation i has a right-image column that the refinement uses.
bool hasRight(const Correspondences& c, std::size_t i, bool enabled) {
  return enabled && !c.u_right.empty() && c.u_right[i] >= 0;
}

/// Right-column residual of p (camera frame, z > 0), normalised by the left
/// sigma times `scale` (PoseEstimationParams::stereo_sigma_scale).
double rightResidual(const Correspondences& c, const PinholeIntrinsics& K, std::size_t i,
                     const Vec3& p, double scale) {
  return (K.fx * (p.x() - c.baseline) / p.z() + K.cx - c.u_right[i]) / (sigmaOf(c, i) * scale);
}

/// Robust reprojection cost 1/2 sum rho(|r_i|^2) over the observations in `use`
/// (Huber rho with width `huber`, r = ReprojectionResidual, plus the right-image
/// column where right_scale > 0 and the observation has one, its sigma scaled by
/// right_scale), and when H and g are
/// given the Gauss-Newton normal equations in the left perturbation
/// T <- (Exp(phi) R, Exp(phi) t + rho), xi = (rho, phi), with IRLS weights rho'.
double robustCost(const Correspondences& c, const PinholeIntrinsics& K, const std::vector<bool>& use,
                  double huber, double right_scale, const Mat3& R, const Vec3& t, Mat6* H, Vec6* g) {
  const bool stereo = right_scale > 0;
  const double a2 = huber * huber;
  double cost = 0;
  if (H) {
    H->setZero();
    g->setZero();
  }
  for (std::size_t i = 0; i < c.size(); ++i) {
    if (!use[i]) continue;
    const Vec3 p = R * c.p_W[i] + t;
    const double inv_s = 1.0 / sigmaOf(c, i);
    if (p.z() <= 1e-6) {  // behind the camera: the residual's constant (1e3, 1e3), no gradient
      cost += 0.5 * (2 * huber * std::sqrt(2e6) - a2);
      continue;
    }
    const double iz = 1.0 / p.z();
    const Vec3 r((K.fx * p.x() * iz + K.cx - c.uv[i].x()) * inv_s,
                 (K.fy * p.y() * iz + K.cy - c.uv[i].y()) * inv_s,
                 hasRight(c, i, stereo) ? rightResidual(c, K, i, p, right_scale) : 0.0);
    const double s = r.squaredNorm();
    double w = 1.0;
    if (s <= a2) {
      cost += 0.5 * s;
    } else {
      const double root = std::sqrt(s);
      cost += 0.5 * (2 * huber * root - a2);
      w = huber / root;
    }
    if (!H) continue;
    Eigen::Matrix<double, 3, 3> Jp;
    Jp << K.fx * iz, 0, -K.fx * p.x() * iz * iz, 0, K.fy * iz, -K.fy * p.y() * iz * iz,
        K.fx * iz, 0, -K.fx * (p.x() - c.baseline) * iz * iz;
    if (!hasRight(c, i, stereo)) Jp.row(2).setZero();
    else Jp.row(2) /= right_scale;
    Jp *= inv_s;
    Eigen::Matrix<double, 3, 6> J;
    J.leftCols<3>() = Jp;
    J.rightCols<3>() = -Jp * hat(p);
    H->noalias() += w * J.transpose() * J;
    g->noalias() += w * J.transpose() * r;
  }
  return cost;
}

/// Levenberg-Marquardt on robustCost, at most `iterations` steps (tried or taken),
/// stopping once the relative cost decrease < 1e-10, the step < 1e-10 relative,
/// or the gradient < 1e-10 (tighter than Ceres' defaults: an iteration costs
/// little here, and the Huber tails make the cost flat near the minimum).
void minimiseRobustCost(const Correspondences& c, const PinholeIntrinsics& K,
                        const std::vector<bool>& use, double huber, double right_scale,
                        int iterations, Mat3* R, Vec3* t) {
  Mat6 H;
  Vec6 g;
  double cost = robustCost(c, K, use, huber, right_scale, *R, *t, &H, &g);
  double lambda = 1e-4;
  for (int it = 0; it < iterations; ++it) {
    if (g.lpNorm<Eigen::Infinity>() < 1e-10) break;
    Mat6 A = H;
    A.diagonal() += lambda * H.diagonal().cwiseMax(1e-6);
    const Vec6 step = A.ldlt().solve(-g);
    if (!step.allFinite()) break;
    const Mat3 dR = expSO3(step.tail<3>());
    const Mat3 R_new = Quat(dR * *R).normalized().toRotationMatrix();
    const Vec3 t_new = dR * *t + step.head<3>();
    const double new_cost = robustCost(c, K, use, huber, right_scale, R_new, t_new, nullptr, nullptr);
    if (new_cost < cost) {
      const bool small_change = cost - new_cost < 1e-10 * cost ||
                                step.norm() < 1e-10 * (t->norm() + 1e-8);
      *R = R_new;
      *t = t_new;
      lambda = std::max(lambda / 3, 1e-12);
      if (small_change) break;
      cost = robustCost(c, K, use, huber, right_scale, *R, *t, &H, &g);
    } else {
      lambda *= 4;
    }
  }
}

}  // namespace

Expected<PoseEstimate> refinePose(const Correspondences& c, const PinholeIntrinsics& K,
                                  const SE3& T_C_W_init, const PoseEstimationParams& p,
                                  const std::vector<bool>* initial_inliers,
                                  const std::vector<bool>* trusted) {
  Status s = checkInput(c, p);
  if (!s) return Error{s.error()};
  const std::size_t n = c.size();
  Mat3 R = T_C_W_init.rotation();
  Vec3 t = T_C_W_init.translation();
  std::vector<bool> inlier(n, true);
  if (initial_inliers) {
    if (initial_inliers->size() != n)
      return Error{"pose refinement: initial inlier mask has the wrong length"};
    inlier = *initial_inliers;
  }
  if (trusted && trusted->size() != n)
    return Error{"pose refinement: trusted mask has the wrong length"};
  std::vector<double> chi2(n, 0.0);

  auto classify = [&]() {
    const Quat q(R);
    const double qa[4] = {q.x(), q.y(), q.z(), q.w()}, ta[3] = {t.x(), t.y(), t.z()};
    for (std::size_t i = 0; i < n; ++i) {
      ReprojectionResidual f(c.uv[i], c.p_W[i], K, sigmaOf(c, i));
      double r[2];
      f(qa, ta, r);
      chi2[i] = r[0] * r[0] + r[1] * r[1];
      const Vec3 pc = R * c.p_W[i] + t;
      if (hasRight(c, i, p.stereo_residual) && pc.z() > 1e-6) {
        const double rr = rightResidual(c, K, i, pc, p.stereo_sigma_scale);
        chi2[i] += rr * rr;
        inlier[i] = chi2[i] <= p.chi2_threshold_stereo;
      } else {
        inlier[i] = chi2[i] <= p.chi2_threshold;
      }
    }
  };
  std::vector<bool> use(n);
  for (int round = 0; round < p.refine_rounds; ++round) {
    for (std::size_t i = 0; i < n; ++i) use[i] = inlier[i] && (!trusted || (*trusted)[i]);
    const int used = int(std::count(use.begin(), use.end(), true));
    if (used < p.min_inliers) break;
    minimiseRobustCost(c, K, use, p.huber_px, p.stereo_residual ? p.stereo_sigma_scale : 0.0,
                       p.iterations_per_round, &R, &t);
    classify();  // every observation, so wrongly rejected ones can come back
  }
  PoseEstimate out;
  out.T_C_W = SE3(R, t);
  out.inlier = inlier;
  double sq = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (!inlier[i]) continue;
    ++out.num_inliers;
    sq += chi2[i] * sigmaOf(c, i) * sigmaOf(c, i);
  }
  if (out.num_inliers < p.min_inliers)
    return Error{"pose refinement: " + std::to_string(out.num_inliers) + " inliers of " +
                 std::to_string(n) + ", need " + std::to_string(p.min_inliers)};
  out.rms_px = std::sqrt(sq / out.num_inliers);
  return out;
}

double projectionShift(const Correspondences& c, const PinholeIntrinsics& K, const SE3& a,
                       const SE3& b) {
  double sum = 0;
  int n = 0;
  for (const Vec3& p : c.p_W) {
    const Vec3 pa = a * p, pb = b * p;
    if (pa.z() <= 1e-6 || pb.z() <= 1e-6) continue;
    sum += (K.project(pa) - K.project(pb)).norm();
    ++n;
  }
  return n > 0 ? sum / n : 0.0;
}

Expected<PoseEstimate> estimatePose(const Correspondences& c, const PinholeIntrinsics& K,
                                    const PoseEstimationParams& p) {
  Status s = checkInput(c, p);
  if (!s) return Error{s.error()};
  std::vector<cv::Point3d> obj(c.size());
  std::vector<cv::Point2d> img(c.size());
  for (std::size_t i = 0; i < c.size(); ++i) {
    obj[i] = cv::Point3d(c.p_W[i].x(), c.p_W[i].y(), c.p_W[i].z());
    img[i] = cv::Point2d(c.uv[i].x(), c.uv[i].y());
  }
  const cv::Matx33d Kcv(K.fx, 0, K.cx, 0, K.fy, K.cy, 0, 0, 1);
  cv::Mat rvec, tvec;
  std::vector<int> inliers;
  bool ok = false;
  try {
    ok = cv::solvePnPRansac(obj, img, Kcv, cv::noArray(), rvec, tvec, false, p.ransac_iterations,
                            float(p.ransac_threshold_px), p.ransac_confidence, inliers,
                            cv::SOLVEPNP_P3P);
  } catch (const cv::Exception& e) {
    return Error{std::string("pose estimation: PnP RANSAC failed: ") + e.what()};
  }
  if (!ok || int(inliers.size()) < p.min_inliers)
    return Error{"pose estimation: PnP RANSAC found " + std::to_string(inliers.size()) +
                 " inliers of " + std::to_string(c.size()) + ", need " +
                 std::to_string(p.min_inliers)};
  cv::Mat Rcv;
  cv::Rodrigues(rvec, Rcv);
  Mat3 R;
  cv::cv2eigen(Rcv, R);
  const SE3 T_init(R, Vec3(tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2)));
  std::vector<bool> mask(c.size(), false);
  for (int i : inliers)
    if (i >= 0 && std::size_t(i) < c.size()) mask[i] = true;
  return refinePose(c, K, T_init, p, &mask);
}

}  // namespace hermes
