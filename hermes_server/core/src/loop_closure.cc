#include "hermes/server/loop_closure.h"

#include <chrono>
#include <cmath>

namespace hermes {
namespace server {

Status LoopClosureParams::read(const Config& config, const std::string& prefix) {
  const std::string p = prefix + ".";
  for (Status s : {matching.read(config, prefix + ".matching"),
                   config.get(p + "ransac_threshold_px", &ransac_threshold_px),
                   config.get(p + "ransac_max_iterations", &ransac_max_iterations),
                   config.get(p + "ransac_probability", &ransac_probability),
                   config.get(p + "ransac_hopeless_iterations", &ransac_hopeless_iterations),
                   config.get(p + "prefilter_pairs", &prefilter_pairs),
                   config.get(p + "prefilter_min_matches", &prefilter_min_matches),
                   config.get(p + "prefilter_max_iterations", &prefilter_max_iterations),
                   config.getChoice(p + "prefilter_solver", {"nister", "stewenius", "sevenpt", "eightpt"},
                                    &prefilter_solver),
                   config.get(p + "min_matches", &min_matches),
                   config.get(p + "min_inliers", &min_inliers),
                   config.get(p + "min_inlier_ratio", &min_inlier_ratio),
                   config.get(p + "refine", &refine),
                   config.get(p + "opengv_refine", &opengv_refine),
                   config.get(p + "refine_max_points", &refine_max_points),
                   config.get(p + "opengv_refine_max_points", &opengv_refine_max_points),
                   config.get(p + "sigma_floor_px", &sigma_floor_px),
                   config.get(p + "covariance_inflation", &covariance_inflation),
                   config.get(p + "max_translation_sigma_m", &max_translation_sigma_m),
                   config.get(p + "sigma_precheck_factor", &sigma_precheck_factor),
                   config.get(p + "depth_focal_baseline_px_m", &depth_focal_baseline_px_m),
                   config.get(p + "deterministic", &deterministic)}) {
    if (!s) return s;
  }
  if (Status s = validate(); !s) return Error{prefix + ": " + s.error()};
  return Status::Ok();
}

void LoopClosureParams::write(ConfigWriter* w, const std::string& prefix) const {
  const std::string p = prefix + ".";
  matching.write(w, prefix + ".matching");
  w->set(p + "ransac_threshold_px", ransac_threshold_px);
  w->set(p + "ransac_max_iterations", ransac_max_iterations);
  w->set(p + "ransac_probability", ransac_probability);
  w->set(p + "ransac_hopeless_iterations", ransac_hopeless_iterations);
  w->set(p + "prefilter_pairs", prefilter_pairs);
  w->set(p + "prefilter_min_matches", prefilter_min_matches);
  w->set(p + "prefilter_max_iterations", prefilter_max_iterations);
  w->set(p + "prefilter_solver", prefilter_solver);
  w->set(p + "min_matches", min_matches);
  w->set(p + "min_inliers", min_inliers);
  w->set(p + "min_inlier_ratio", min_inlier_ratio);
  w->set(p + "refine", refine);
  w->set(p + "opengv_refine", opengv_refine);
  w->set(p + "refine_max_points", refine_max_points);
  w->set(p + "opengv_refine_max_points", opengv_refine_max_points);
  w->set(p + "sigma_floor_px", sigma_floor_px);
  w->set(p + "covariance_inflation", covariance_inflation);
  w->set(p + "max_translation_sigma_m", max_translation_sigma_m);
  w->set(p + "sigma_precheck_factor", sigma_precheck_factor);
  w->set(p + "depth_focal_baseline_px_m", depth_focal_baseline_px_m);
  w->set(p + "deterministic", deterministic);
}

Status LoopClosureParams::validate() const {
  if (Status s = matching.validate(); !s) return s;
  if (!(ransac_threshold_px > 0)) return Error{"ransac_threshold_px must be > 0"};
  if (ransac_max_iterations < 1) return Error{"ransac_max_iterations must be >= 1"};
  if (!(ransac_probability > 0 && ransac_probability < 1)) return Error{"ransac_probability must be in (0, 1)"};
  if (ransac_hopeless_iterations < 0) return Error{"ransac_hopeless_iterations must be >= 0 (0 = off)"};
  if (prefilter_min_matches < 8) return Error{"prefilter_min_matches must be >= 8 (minimal samples up to 8)"};
  if (prefilter_max_iterations < 1) return Error{"prefilter_max_iterations must be >= 1"};
  if (prefilter_solver != "nister" && prefilter_solver != "stewenius" &&
      prefilter_solver != "sevenpt" && prefilter_solver != "eightpt") {
    return Error{"prefilter_solver must be nister, stewenius, sevenpt or eightpt"};
  }
  if (min_matches < 18) return Error{"min_matches must be >= 18 (17-point solver)"};
  if (min_inliers < 18) return Error{"min_inliers must be >= 18 (17-point solver)"};
  if (!(min_inlier_ratio >= 0 && min_inlier_ratio <= 1)) return Error{"min_inlier_ratio must be in [0, 1]"};
  if (!(sigma_floor_px > 0)) return Error{"sigma_floor_px must be > 0"};
  if (refine_max_points != 0 && refine_max_points < 18)
    return Error{"refine_max_points must be 0 (all) or >= 18 (17-point solver)"};
  if (opengv_refine_max_points != 0 && opengv_refine_max_points < 18)
    return Error{"opengv_refine_max_points must be 0 (refine_max_points) or >= 18"};
  if (!(covariance_inflation > 0)) return Error{"covariance_inflation must be > 0"};
  if (!(max_translation_sigma_m > 0)) return Error{"max_translation_sigma_m must be > 0"};
  if (!(sigma_precheck_factor == 0 || sigma_precheck_factor >= 1))
    return Error{"sigma_precheck_factor must be 0 (off) or >= 1"};
  if (!(depth_focal_baseline_px_m >= 0)) return Error{"depth_focal_baseline_px_m must be >= 0"};
  return Status::Ok();
}

const char* toString(LoopStatus status) {
  switch (status) {
    case LoopStatus::kAccepted: return "accepted";
    case LoopStatus::kBadInput: return "bad_input";
    case LoopStatus::kTooFewMatches: return "too_few_matches";
    case LoopStatus::kRansacFailed: return "ransac_failed";
    case LoopStatus::kTooFewInliers: return "too_few_inliers";
    case LoopStatus::kDegenerate: return "degenerate";
    case LoopStatus::kSkippedDuplicate: return "skipped_duplicate";
    case LoopStatus::kSkippedBudget: return "skipped_budget";
  }
  return "unknown";
}

GeneralizedCorrespondences makeCorrespondences(const Rig& query, const Rig& candidate,
                                               const std::vector<RigMatch>& matches) {
  GeneralizedCorrespondences corr;
  corr.T_refQ_Cq = query.T_ref_C;
  corr.T_refC_Cc = candidate.T_ref_C;
  double focal_sum = 0;
  int focal_n = 0;
  for (const auto* rig : {&query, &candidate}) {
    for (const PinholeIntrinsics& k : rig->intrinsics) {
      focal_sum += 0.5 * (k.fx + k.fy);
      ++focal_n;
    }
  }
  if (focal_n > 0) corr.focal_px = focal_sum / focal_n;
  for (const RigMatch& m : matches) {
    const Keypoint& kq = query.keyframes[m.cam_q]->keypoints[m.kp_q];
    const Keypoint& kc = candidate.keyframes[m.cam_c]->keypoints[m.kp_c];
    corr.bearings_q.push_back(query.intrinsics[m.cam_q].bearing(Vec2(kq.u, kq.v)));
    corr.bearings_c.push_back(candidate.intrinsics[m.cam_c].bearing(Vec2(kc.u, kc.v)));
    corr.cam_q.push_back(m.cam_q);
    corr.cam_c.push_back(m.cam_c);
    corr.depths_q.push_back(kq.depth > 0 && std::isfinite(kq.depth) ? kq.depth : 0.0);
    corr.depths_c.push_back(kc.depth > 0 && std::isfinite(kc.depth) ? kc.depth : 0.0);
  }
  return corr;
}

LoopCloser::LoopCloser(const LoopClosureParams& params) : params_(params) {}

LoopClosureResult LoopCloser::close(const Rig& query, const Rig& candidate) const {
  const auto t0 = std::chrono::steady_clock::now();
  // Keypoints with non-finite coordinates (corrupt data) are dropped here so that
  // one bad keypoint does not invalidate the whole attempt.
  std::vector<RigMatch> matches;
  for (const RigMatch& m : matchRigs(query, candidate, params_.matching)) {
    const Keypoint& kq = query.keyframes[m.cam_q]->keypoints[m.kp_q];
    const Keypoint& kc = candidate.keyframes[m.cam_c]->keypoints[m.kp_c];
    if (std::isfinite(kq.u) && std::isfinite(kq.v) && std::isfinite(kc.u) && std::isfinite(kc.v)) {
      matches.push_back(m);
    }
  }
  LoopClosureResult res =
      solveGeneralizedRelativePose(makeCorrespondences(query, candidate, matches), params_);
  for (int i : res.inliers) res.inlier_matches.push_back(matches[i]);
  res.time_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  return res;
}

LoopClosureResult LoopCloser::close(const Keyframe& query,
                                    const std::vector<const Keyframe*>& query_neighbours,
                                    const std::vector<PinholeIntrinsics>& query_cameras,
                                    const Keyframe& candidate,
                                    const std::vector<const Keyframe*>& candidate_neighbours,
                                    const std::vector<PinholeIntrinsics>& candidate_cameras) const {
  Expected<Rig> rq = makeRig(query, query_neighbours, query_cameras);
  Expected<Rig> rc = makeRig(candidate, candidate_neighbours, candidate_cameras);
  if (!rq || !rc) {
    LoopClosureResult res;
    res.status = LoopStatus::kBadInput;
    res.reason = !rq ? "query rig: " + rq.error() : "candidate rig: " + rc.error();
    return res;
  }
  return close(*rq, *rc);
}

}  // namespace server
}  // namespace hermes
