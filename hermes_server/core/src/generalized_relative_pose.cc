// 17-point generalized relative pose: per-pair pre-filter, OpenGV RANSAC,
// OpenGV non-linear refinement, then the bundle-adjustment refinement and the
// edge information (loop_refinement.cc).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <memory>

#include <opengv/relative_pose/CentralRelativeAdapter.hpp>
#include <opengv/relative_pose/NoncentralRelativeAdapter.hpp>
#include <opengv/relative_pose/methods.hpp>
#include <opengv/sac/Ransac.hpp>
#include <opengv/sac_problems/relative_pose/CentralRelativePoseSacProblem.hpp>
#include <opengv/sac_problems/relative_pose/NoncentralRelativePoseSacProblem.hpp>

#include "hermes/server/loop_closure.h"
#include "loop_refinement.h"

namespace hermes {
namespace server {

namespace {

using Clock = std::chrono::steady_clock;
using CentralProblem = opengv::sac_problems::relative_pose::CentralRelativePoseSacProblem;
using NoncentralProblem = opengv::sac_problems::relative_pose::NoncentralRelativePoseSacProblem;

double msSince(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

/// OpenGV scores a correspondence by 1 - cos(angle) between each observed bearing
/// and the reprojection of the triangulated point, summed over both views.
double sacThreshold(double px, double focal) {
  return 2.0 * (1.0 - std::cos(std::atan(px / focal)));
}

/// Central 5-point RANSAC per (query camera, candidate camera) pair; returns the
/// surviving correspondence indices. Pairs with too few matches are dropped.
std::vector<int> prefilterPairs(const GeneralizedCorrespondences& corr,
                                const opengv::bearingVectors_t& b1,
                                const opengv::bearingVectors_t& b2,
                                const LoopClosureParams& params, double threshold) {
  std::map<std::pair<int, int>, std::vector<int>> groups;
  for (std::size_t i = 0; i < corr.size(); ++i) {
    groups[{corr.cam_q[i], corr.cam_c[i]}].push_back(static_cast<int>(i));
  }
  opengv::relative_pose::CentralRelativeAdapter adapter(b1, b2);
  CentralProblem::algorithm_t algorithm = CentralProblem::NISTER;
  if (params.prefilter_solver == "stewenius") algorithm = CentralProblem::STEWENIUS;
  if (params.prefilter_solver == "sevenpt") algorithm = CentralProblem::SEVENPT;
  if (params.prefilter_solver == "eightpt") algorithm = CentralProblem::EIGHTPT;
  std::vector<int> kept;
  for (const auto& [pair, idx] : groups) {
    if (static_cast<int>(idx.size()) < params.prefilter_min_matches) continue;
    opengv::sac::Ransac<CentralProblem> ransac;
    ransac.sac_model_ = std::make_shared<CentralProblem>(adapter, algorithm, idx,
                                                         !params.deterministic);
    ransac.threshold_ = threshold;
    ransac.max_iterations_ = params.prefilter_max_iterations;
    ransac.probability_ = 0.99;
    if (!ransac.computeModel()) continue;
    if (static_cast<int>(ransac.inliers_.size()) < 5) continue;
    kept.insert(kept.end(), ransac.inliers_.begin(), ransac.inliers_.end());
  }
  std::sort(kept.begin(), kept.end());
  return kept;
}

SE3 toSE3(const opengv::transformation_t& m) {
  return SE3(Mat3(m.block<3, 3>(0, 0)), Vec3(m.col(3)));
}

}  // namespace

std::string GeneralizedCorrespondences::validate() const {
  const std::size_t n = bearings_q.size();
  if (bearings_c.size() != n || cam_q.size() != n || cam_c.size() != n) {
    return "correspondence arrays differ in length";
  }
  if (!(focal_px > 0)) return "focal_px must be positive";
  for (const auto& v : {T_refQ_Cq, T_refC_Cc}) {
    for (const SE3& T : v) {
      if (!T.translation().allFinite() || !T.quat().coeffs().allFinite()) return "non-finite camera offset";
    }
  }
  if ((!depths_q.empty() && depths_q.size() != n) || (!depths_c.empty() && depths_c.size() != n)) {
    return "depth arrays must be empty or as long as the correspondences";
  }
  for (std::size_t i = 0; i < n; ++i) {
    if (!(std::isfinite(depthQ(i)) && depthQ(i) >= 0 && std::isfinite(depthC(i)) && depthC(i) >= 0)) {
      return "correspondence " + std::to_string(i) + " has a negative or non-finite depth";
    }
    if (cam_q[i] < 0 || cam_q[i] >= static_cast<int>(T_refQ_Cq.size()) || cam_c[i] < 0 ||
        cam_c[i] >= static_cast<int>(T_refC_Cc.size())) {
      return "correspondence " + std::to_string(i) + " has a camera index out of range";
    }
    if (!bearings_q[i].allFinite() || !bearings_c[i].allFinite() ||
        std::abs(bearings_q[i].norm() - 1) > 1e-6 || std::abs(bearings_c[i].norm() - 1) > 1e-6) {
      return "correspondence " + std::to_string(i) + " has a non-unit bearing";
    }
  }
  return "";
}

LoopClosureResult solveGeneralizedRelativePose(const GeneralizedCorrespondences& corr,
                                               const LoopClosureParams& params) {
  const auto t0 = Clock::now();
  LoopClosureResult res;
  auto finish = [&](LoopStatus s, std::string reason) {
    res.status = s;
    res.reason = std::move(reason);
    res.time_ms = msSince(t0);
    return res;
  };
  if (Status s = params.validate(); !s) return finish(LoopStatus::kBadInput, s.error());
  if (std::string e = corr.validate(); !e.empty()) return finish(LoopStatus::kBadInput, e);
  res.num_matches = static_cast<int>(corr.size());
  const int need = std::max({params.min_matches, params.min_inliers, 18});
  if (res.num_matches < need) {
    return finish(LoopStatus::kTooFewMatches, std::to_string(res.num_matches) +
                                                  " correspondences < " + std::to_string(need));
  }

  opengv::bearingVectors_t b1(corr.bearings_q.begin(), corr.bearings_q.end());
  opengv::bearingVectors_t b2(corr.bearings_c.begin(), corr.bearings_c.end());
  const double threshold = sacThreshold(params.ransac_threshold_px, corr.focal_px);

  std::vector<int> indices;
  if (params.prefilter_pairs) {
    const auto t_pre = Clock::now();
    indices = prefilterPairs(corr, b1, b2, params, threshold);
    res.prefilter_ms = msSince(t_pre);
  } else {
    indices.resize(corr.size());
    for (std::size_t i = 0; i < corr.size(); ++i) indices[i] = static_cast<int>(i);
  }
  res.num_prefiltered = static_cast<int>(indices.size());
  if (res.num_prefiltered < std::max(params.min_inliers, 18)) {
    return finish(LoopStatus::kTooFewMatches,
                  std::to_string(res.num_prefiltered) + " correspondences left after the per-pair "
                  "pre-filter (< " + std::to_string(std::max(params.min_inliers, 18)) + ")");
  }

  // Both rigs share one camera table: query cameras first, then candidate cameras.
  opengv::translations_t offsets;
  opengv::rotations_t rotations;
  for (const SE3& T : corr.T_refQ_Cq) { offsets.push_back(T.translation()); rotations.push_back(T.rotation()); }
  for (const SE3& T : corr.T_refC_Cc) { offsets.push_back(T.translation()); rotations.push_back(T.rotation()); }
  std::vector<int> cc1(corr.cam_q.begin(), corr.cam_q.end());
  std::vector<int> cc2(corr.cam_c.size());
  const int nq = static_cast<int>(corr.T_refQ_Cq.size());
  for (std::size_t i = 0; i < cc2.size(); ++i) cc2[i] = corr.cam_c[i] + nq;
  opengv::relative_pose::NoncentralRelativeAdapter adapter(b1, b2, cc1, cc2, offsets, rotations);

  const auto t_ransac = Clock::now();
  opengv::sac::Ransac<NoncentralProblem> ransac;
  auto problem = std::make_shared<NoncentralProblem>(adapter, NoncentralProblem::SEVENTEENPT,
                                                     indices, false, !params.deterministic);
  ransac.sac_model_ = problem;
  ransac.threshold_ = threshold;
  ransac.max_iterations_ = params.ransac_max_iterations;
  ransac.probability_ = params.ransac_probability;
  const bool found = ransac.computeModel();
  res.ransac_ms = msSince(t_ransac);
  res.ransac_iterations = ransac.iterations_;
  if (!found || !ransac.model_coefficients_.allFinite()) {
    return finish(LoopStatus::kRansacFailed, "17-point RANSAC found no model");
  }
  opengv::transformation_t model = ransac.model_coefficients_;
  std::vector<int> inliers = ransac.inliers_;

  const auto t_refine = Clock::now();
  if (params.refine && params.opengv_refine && static_cast<int>(inliers.size()) >= 18) {
    adapter.sett12(model.col(3));
    adapter.setR12(model.block<3, 3>(0, 0));
    // On at most refine_max_points evenly spaced inliers (as the bundle adjustment).
    std::vector<int> subset = inliers;
    const std::size_t cap = static_cast<std::size_t>(params.refine_max_points);
    if (cap > 0 && inliers.size() > cap) {
      subset.resize(cap);
      for (std::size_t j = 0; j < cap; ++j) subset[j] = inliers[j * inliers.size() / cap];
    }
    const opengv::transformation_t refined =
        opengv::relative_pose::optimize_nonlinear(adapter, subset);
    if (refined.allFinite()) {
      std::vector<int> refined_inliers;
      problem->selectWithinDistance(refined, threshold, refined_inliers);
      if (refined_inliers.size() >= inliers.size()) {
        model = refined;
        inliers = refined_inliers;
      }
    }
  }
  // Maximum-likelihood refinement (points + pose), re-selection of the inliers
  // by reprojection error (also enforces cheirality) and the edge information.
  const detail::Refinement ref = detail::refineGeneralizedPose(corr, inliers, toSE3(model), params);
  res.refine_ms = msSince(t_refine);
  res.T_refQ_refC = ref.T_refQ_refC;
  res.inliers = ref.inliers;
  res.num_inliers = static_cast<int>(ref.inliers.size());
  res.num_depth_inliers = ref.depth_inliers;
  res.sigma_px = ref.sigma_px;
  const double ratio = static_cast<double>(res.num_inliers) / res.num_matches;
  if (res.num_inliers < params.min_inliers || ratio < params.min_inlier_ratio) {
    return finish(LoopStatus::kTooFewInliers,
                  std::to_string(res.num_inliers) + " inliers of " +
                      std::to_string(res.num_matches) + " (need " +
                      std::to_string(params.min_inliers) + " and ratio " +
                      std::to_string(params.min_inlier_ratio) + ")");
  }
  if (!ref.ok) return finish(LoopStatus::kDegenerate, ref.reason);
  res.information = ref.information;
  res.covariance = ref.covariance;
  return finish(LoopStatus::kAccepted, "");
}

}  // namespace server
}  // namespace hermes
