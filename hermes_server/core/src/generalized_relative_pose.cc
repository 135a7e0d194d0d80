// 17-point generalized relative pose: per-pair pre-filter, OpenGV RANSAC,
// OpenGV non-linear refinement, then the bundle-adjustment refinement and the
// edge information (loop_refinement.cc).
#include <algorithm>
#include <chrono>
#include <climits>
#include <cmath>
#include <limits>
#include <map>
#include <memory>

#include <opengv/relative_pose/CentralRelativeAdapter.hpp>
#include <opengv/relative_pose/NoncentralRelativeAdapter.hpp>
#include <opengv/relative_pose/methods.hpp>
#include <opengv/sac/Ransac.hpp>
#include <opengv/sac_problems/relative_pose/CentralRelativePoseSacProblem.hpp>
#include <opengv/sac_problems/relative_pose/NoncentralRelativePoseSacProblem.hpp>

#include "hermes/core/stopwatch.h"
#include "hermes/server/loop_closure.h"
#include "loop_refinement.h"

namespace hermes {
namespace server {

namespace {

using Clock = std::chrono::steady_clock;
using CentralProblem = opengv::sac_problems::relative_pose::CentralRelativePoseSacProblem;
using NoncentralProblem = opengv::sac_problems::relative_pose::NoncentralRelativePoseSacProblem;

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
    // OpenGV's 5-point solvers throw on some degenerate samples (Nister's
    // Sturm bracketing: std::length_error from vector::reserve, seen in the
    // soak's last wave): a camera pair whose model cannot be computed keeps no
    // correspondence, as one without a model.
    try {
      if (!ransac.computeModel()) continue;
    } catch (const std::exception&) {
      continue;
    }
    if (static_cast<int>(ransac.inliers_.size()) < 5) continue;
    kept.insert(kept.end(), ransac.inliers_.begin(), ransac.inliers_.end());
  }
  std::sort(kept.begin(), kept.end());
  return kept;
}

/// Fewest inliers that pass the final check (min_inliers and min_inlier_ratio of
/// the putative matches).
int inliersNeeded(const LoopClosureParams& params, int num_matches) {
  int n = std::max(params.min_inliers, static_cast<int>(params.min_inlier_ratio * num_matches));
  while (static_cast<double>(n) / num_matches < params.min_inlier_ratio) ++n;
  return n;
}

/// Inliers the sigma pre-check looks at (evenly spaced): a few ms per loop.
constexpr int kPrecheckPoints = 200;

/// What the 17-point RANSAC found.
struct SacOutcome {
  bool found = false;
  opengv::transformation_t model;
  std::vector<int> inliers;
  int iterations = 0;
  int enough_at = -1;     ///< iteration whose model first had `need` inliers (-1 = none)
  bool gave_up = false;   ///< stopped by ransac_hopeless_iterations
};

/// OpenGV's Ransac::computeModel (the same samples, models and stopping rule for
/// one seed) that also gives up after params.ransac_hopeless_iterations
/// iterations (0 = never) while no model had `need` inliers: the verdict could
/// only be "too few inliers" unless a rare later sample is better. A true loop's
/// pre-filtered matches are mostly inliers, so it finds such a model within a
/// few iterations; a place that is no loop runs to the iteration cap.
SacOutcome runRansac(NoncentralProblem* problem, double threshold, const LoopClosureParams& params,
                     int need) {
  SacOutcome out;
  int best = -INT_MAX;
  double k = 1.0;
  unsigned skipped = 0;
  const unsigned max_skip = static_cast<unsigned>(params.ransac_max_iterations) * 10;
  const double n = static_cast<double>(problem->getIndices()->size());
  std::vector<int> sample;
  opengv::transformation_t model;
  while (out.iterations < k && skipped < max_skip) {
    problem->getSamples(out.iterations, sample);
    if (sample.empty()) break;
    if (!problem->computeModelCoefficients(sample, model)) {
      ++skipped;
      continue;
    }
    const int count = problem->countWithinDistance(model, threshold);
    if (count > best) {
      best = count;
      out.found = true;
      out.model = model;
      if (out.enough_at < 0 && count >= need) out.enough_at = out.iterations;
      const double eps = std::numeric_limits<double>::epsilon();
      const double p_bad = std::clamp(1.0 - std::pow(best / n, static_cast<double>(sample.size())),
                                      eps, 1.0 - eps);
      k = std::log(1.0 - params.ransac_probability) / std::log(p_bad);
    }
    ++out.iterations;
    if (out.iterations > params.ransac_max_iterations) break;
    if (params.ransac_hopeless_iterations > 0 && out.iterations >= params.ransac_hopeless_iterations &&
        best < need) {
      out.gave_up = true;
      break;
    }
  }
  if (out.found) problem->selectWithinDistance(out.model, threshold, out.inliers);
  return out;
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
  const int need_matches = std::max({params.min_matches, params.min_inliers, 18});
  if (res.num_matches < need_matches) {
    return finish(LoopStatus::kTooFewMatches, std::to_string(res.num_matches) +
                                                  " correspondences < " + std::to_string(need_matches));
  }
  // Inliers the verdict needs. Every later inlier set is a subset of the
  // pre-filtered matches (RANSAC, OpenGV refinement) or of the previous set
  // (bundle adjustment), so a set below this ends the attempt exactly as the
  // final check would, without the remaining stages.
  const int need = inliersNeeded(params, res.num_matches);
  auto tooFew = [&](LoopStatus s, int n, const char* where) {
    res.num_inliers = n;
    return finish(s, std::to_string(n) + " " + where + " of " + std::to_string(res.num_matches) +
                         " (need " + std::to_string(need) + ": min_inliers " +
                         std::to_string(params.min_inliers) + ", ratio " +
                         std::to_string(params.min_inlier_ratio) + ")");
  };

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
  if (res.num_prefiltered < need) {
    return tooFew(LoopStatus::kTooFewMatches, res.num_prefiltered, "matches left by the pre-filter");
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
  NoncentralProblem problem(adapter, NoncentralProblem::SEVENTEENPT, indices, false,
                            !params.deterministic);
  SacOutcome sac = runRansac(&problem, threshold, params, need);
  res.ransac_ms = msSince(t_ransac);
  res.ransac_iterations = sac.iterations;
  res.ransac_enough_at = sac.enough_at;
  if (sac.gave_up) {
    return tooFew(LoopStatus::kRansacFailed, static_cast<int>(sac.inliers.size()),
                  "RANSAC inliers at ransac_hopeless_iterations");
  }
  if (!sac.found || !sac.model.allFinite()) {
    return finish(LoopStatus::kRansacFailed, "17-point RANSAC found no model");
  }
  opengv::transformation_t model = sac.model;
  std::vector<int> inliers = std::move(sac.inliers);
  const auto t_refine = Clock::now();
  if (params.refine && params.opengv_refine && static_cast<int>(inliers.size()) >= 18) {
    adapter.sett12(model.col(3));
    adapter.setR12(model.block<3, 3>(0, 0));
    // On at most opengv_refine_max_points (else refine_max_points, as the bundle
    // adjustment) evenly spaced inliers.
    std::vector<int> subset = inliers;
    const std::size_t cap = static_cast<std::size_t>(
        params.opengv_refine_max_points > 0 ? params.opengv_refine_max_points : params.refine_max_points);
    if (cap > 0 && inliers.size() > cap) {
      subset.resize(cap);
      for (std::size_t j = 0; j < cap; ++j) subset[j] = inliers[j * inliers.size() / cap];
    }
    const opengv::transformation_t refined =
        opengv::relative_pose::optimize_nonlinear(adapter, subset);
    if (refined.allFinite()) {
      std::vector<int> refined_inliers;
      problem.selectWithinDistance(refined, threshold, refined_inliers);
      if (refined_inliers.size() >= inliers.size()) {
        model = refined;
        inliers = refined_inliers;
      }
    }
  }
  if (static_cast<int>(inliers.size()) < need) {
    res.refine_ms = msSince(t_refine);
    return tooFew(LoopStatus::kTooFewInliers, static_cast<int>(inliers.size()), "RANSAC inliers");
  }
  // The bundle adjustment keeps a subset of these inliers at a noise of at
  // least the floor: a sigma already far above the limit here stays above it.
  if (params.sigma_precheck_factor > 0) {
    const double bound = detail::translationSigmaBound(corr, inliers, toSE3(model), params, kPrecheckPoints);
    res.refine_ms = msSince(t_refine);
    if (bound > params.sigma_precheck_factor * params.max_translation_sigma_m) {
      res.num_inliers = static_cast<int>(inliers.size());
      return finish(LoopStatus::kDegenerate,
                    "translation poorly constrained before the bundle adjustment (sigma >= " +
                        std::to_string(bound) + " m > " +
                        std::to_string(params.sigma_precheck_factor) + " x " +
                        std::to_string(params.max_translation_sigma_m) + " m)");
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
  if (res.num_inliers < need) return tooFew(LoopStatus::kTooFewInliers, res.num_inliers, "inliers");
  if (!ref.ok) return finish(LoopStatus::kDegenerate, ref.reason);
  res.information = ref.information;
  res.covariance = ref.covariance;
  return finish(LoopStatus::kAccepted, "");
}

}  // namespace server
}  // namespace hermes
