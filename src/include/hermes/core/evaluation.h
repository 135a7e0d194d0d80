// Trajectory accuracy against ground truth: timestamp association, alignment,
// absolute trajectory error (ATE), relative pose error (RPE), and the
// multi-agent "merged" ATE (all agents aligned with one common transform).
#pragma once

#include <string>
#include <vector>

#include "hermes/core/alignment.h"
#include "hermes/core/config.h"
#include "hermes/core/trajectory.h"

namespace hermes {
namespace eval {

/// Keys under section "eval." (e.g. eval.max_dt).
struct EvalParams {
  AlignMode align = AlignMode::kSE3;
  double max_dt = 0.02;         ///< [s] max distance to the nearest gt sample
  double rpe_delta_s = 1.0;     ///< [s] RPE pair spacing (used if rpe_delta_frames == 0)
  int rpe_delta_frames = 0;     ///< RPE pair spacing in matched poses (> 0 overrides seconds)
  /// Time-based RPE pairs (i, j): j is the first matched pose with t_j >= t_i + delta;
  /// the pair is dropped when t_j - t_i > (1 + rpe_tolerance) * delta.
  double rpe_tolerance = 0.1;

  Status read(const Config& config, const std::string& section = "eval");
  Status validate() const;
};

/// Estimate poses paired with ground truth at the same time.
struct Association {
  std::vector<double> t;   ///< [s] estimate stamps that matched
  std::vector<SE3> gt;     ///< gt pose interpolated at t
  std::vector<SE3> est;    ///< estimate pose at t
  size_t unmatched = 0;    ///< estimate poses without gt within max_dt
  size_t matched() const { return t.size(); }
};

/// For every estimate pose: matched when the nearest gt sample is within max_dt;
/// the gt pose is then interpolated (interpolatePose) between the bracketing
/// samples, or taken from the end sample when t lies just outside the gt span.
/// Errors: gt empty or not strictly increasing in time.
Expected<Association> associate(const Trajectory& gt, const Trajectory& est, double max_dt);

/// Angle [rad] of a^-1 * b, accurate also near 0 (atan2 form; acos of the trace
/// loses ~1e-8 rad there).
double relativeAngle(const Quat& a, const Quat& b);

/// Summary of a list of non-negative errors.
struct ErrorStats {
  size_t count = 0;
  double rmse = 0, mean = 0, median = 0, max = 0, min = 0, std = 0;  ///< std: population
};
ErrorStats computeStats(std::vector<double> values);

struct AteResult {
  Alignment alignment;
  ErrorStats trans_m;    ///< ||p_gt - align(p_est)||
  ErrorStats rot_deg;    ///< angle(R_gt^T * R_gt_est * R_est)
  std::vector<double> trans_errors_m;  ///< per matched pose, association order
};

struct RpeResult {
  size_t pairs = 0;
  double delta = 0;          ///< the spacing used ([s], or frames if by_frames)
  bool by_frames = false;
  ErrorStats trans_m;        ///< ||translation of (G_i^-1 G_j)^-1 (E_i^-1 E_j)||
  ErrorStats rot_deg;        ///< rotation angle of the same
};

/// ATE of matched poses under the given alignment (computed here by mode).
Expected<AteResult> computeAte(const Association& assoc, AlignMode mode);
/// ATE under a given alignment (e.g. a common one for several agents).
AteResult ateWithAlignment(const Association& assoc, const Alignment& alignment);
/// RPE of matched poses; the estimate is first mapped through `alignment`, so that
/// only a Sim(3) scale matters (rigid alignment leaves relative poses unchanged).
RpeResult computeRpe(const Association& assoc, const Alignment& alignment,
                     const EvalParams& params);

/// Everything about one (gt, estimate) pair.
struct TrajectoryEval {
  std::string name;
  size_t est_poses = 0;
  Association assoc;
  AteResult ate;
  RpeResult rpe;
};

/// Associates, aligns (separately), computes ATE and RPE. Error when nothing matched
/// or the alignment is impossible; the message starts with `name`.
Expected<TrajectoryEval> evaluateTrajectory(const Trajectory& gt, const Trajectory& est,
                                            const EvalParams& params,
                                            const std::string& name = "estimate");

/// One agent's input to the multi-agent evaluation.
struct AgentTrajectories {
  std::string name;
  Trajectory gt;
  Trajectory est;  ///< in the merged (common world) frame for a merged run
};

struct AgentFailure {
  std::string name;
  std::string error;
};

struct MultiAgentEval {
  std::vector<TrajectoryEval> agents;  ///< each aligned on its own (evaluated ones only)
  std::vector<AgentFailure> failed;    ///< only with allow_partial
  Alignment merged_alignment;          ///< ONE transform for all agents' poses
  AteResult merged_ate;                ///< over all matched poses of all agents
  std::vector<ErrorStats> merged_per_agent_m;  ///< each agent's share of merged_ate
  size_t matched = 0, unmatched = 0;
};

/// Per-agent and merged evaluation. For the merged ATE every agent's matched
/// (gt, est) poses are pooled and aligned with one transform (kFirstPose: the first
/// agent's first pair), so an agent whose map is offset from the others shows up.
/// Any agent that cannot be evaluated (e.g. nothing matched) is an error, unless
/// allow_partial: then it is listed in `failed` and left out of the merged ATE (an
/// error only when no agent can be evaluated).
Expected<MultiAgentEval> evaluateAgents(const std::vector<AgentTrajectories>& agents,
                                        const EvalParams& params, bool allow_partial = false);

}  // namespace eval
}  // namespace hermes
