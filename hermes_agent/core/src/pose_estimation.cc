#include "hermes/agent/pose_estimation.h"

#include <cmath>

#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

namespace hermes {

Status PoseEstimationParams::read(const Config& c, const std::string& p) {
  for (auto [key, ptr] : {std::pair<const char*, double*>{"ransac_threshold_px", &ransac_threshold_px},
                          {"ransac_confidence", &ransac_confidence},
                          {"huber_px", &huber_px},
                          {"chi2_threshold", &chi2_threshold}}) {
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
  return validate();
}

void PoseEstimationParams::write(ConfigWriter* w, const std::string& p) const {
  w->set(p + ".ransac_threshold_px", ransac_threshold_px);
  w->set(p + ".ransac_iterations", ransac_iterations);
  w->set(p + ".ransac_confidence", ransac_confidence);
  w->set(p + ".huber_px", huber_px);
  w->set(p + ".chi2_threshold", chi2_threshold);
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
  if (refine_rounds < 1) return Error{"pose.refine_rounds must be >= 1"};
  if (iterations_per_round < 1) return Error{"pose.iterations_per_round must be >= 1"};
  if (min_inliers < 4) return Error{"pose.min_inliers must be >= 4"};
  return Status::Ok();
}

namespace {

Status checkInput(const Correspondences& c, const PoseEstimationParams& p) {
  if (c.uv.size() != c.p_W.size() || (!c.sigma_px.empty() && c.sigma_px.size() != c.p_W.size()))
    return Error{"pose estimation: correspondence arrays differ in length"};
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

}  // namespace

Expected<PoseEstimate> refinePose(const Correspondences& c, const PinholeIntrinsics& K,
                                  const SE3& T_C_W_init, const PoseEstimationParams& p,
                                  const std::vector<bool>* initial_inliers) {
  Status s = checkInput(c, p);
  if (!s) return Error{s.error()};
  const std::size_t n = c.size();
  Quat q = T_C_W_init.quat();
  double qa[4] = {q.x(), q.y(), q.z(), q.w()};
  Vec3 tv = T_C_W_init.translation();
  double ta[3] = {tv.x(), tv.y(), tv.z()};
  std::vector<bool> inlier(n, true);
  if (initial_inliers) {
    if (initial_inliers->size() != n)
      return Error{"pose refinement: initial inlier mask has the wrong length"};
    inlier = *initial_inliers;
  }
  std::vector<double> chi2(n, 0.0);

  auto classify = [&]() {
    for (std::size_t i = 0; i < n; ++i) {
      ReprojectionResidual f(c.uv[i], c.p_W[i], K, sigmaOf(c, i));
      double r[2];
      f(qa, ta, r);
      chi2[i] = r[0] * r[0] + r[1] * r[1];
      inlier[i] = chi2[i] <= p.chi2_threshold;
    }
  };
  for (int round = 0; round < p.refine_rounds; ++round) {
    ceres::Problem::Options po;
    po.manifold_ownership = ceres::TAKE_OWNERSHIP;
    ceres::Problem problem(po);
    problem.AddParameterBlock(qa, 4, new ceres::EigenQuaternionManifold());
    problem.AddParameterBlock(ta, 3);
    int used = 0;
    for (std::size_t i = 0; i < n; ++i) {
      if (!inlier[i]) continue;
      problem.AddResidualBlock(ReprojectionResidual::create(c.uv[i], c.p_W[i], K, sigmaOf(c, i)),
                               new ceres::HuberLoss(p.huber_px), qa, ta);
      ++used;
    }
    if (used < p.min_inliers) break;
    ceres::Solver::Options so;
    so.linear_solver_type = ceres::DENSE_QR;
    so.max_num_iterations = p.iterations_per_round;
    so.num_threads = 1;
    so.logging_type = ceres::SILENT;
    ceres::Solver::Summary summary;
    ceres::Solve(so, &problem, &summary);
    classify();  // every observation, so wrongly rejected ones can come back
  }
  PoseEstimate out;
  out.T_C_W = SE3(Quat(qa[3], qa[0], qa[1], qa[2]), Vec3(ta[0], ta[1], ta[2]));
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
