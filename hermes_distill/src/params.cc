#include "hermes/distill/params.h"

#include <algorithm>
#include <cctype>
#include <cmath>

namespace hermes {
namespace distill {
namespace {

const char* kPrefix = "distill.";

// Accepts on/off, true/false, yes/no, 1/0 (YAML may hand either form over).
Status readOnOff(const Config& c, const std::string& key, bool* out) {
  if (!c.has(key)) return Status::Ok();
  std::string v = *out ? "on" : "off";
  Status s = c.get(key, &v);
  if (!s) return s;
  std::transform(v.begin(), v.end(), v.begin(), [](unsigned char ch) { return std::tolower(ch); });
  if (v == "on" || v == "true" || v == "yes" || v == "1") {
    *out = true;
  } else if (v == "off" || v == "false" || v == "no" || v == "0") {
    *out = false;
  } else {
    return Error{"config " + c.origin() + ": key '" + key + "' is '" + v + "', expected on | off"};
  }
  return Status::Ok();
}

}  // namespace

Status DistillParams::read(const Config& c) {
  const std::string p = kPrefix;
  Status s = c.getChoice(p + "strategy", {"milp", "greedy_logdet", "stability", "anms", "none"},
                         &strategy);
  if (s) s = c.getChoice(p + "tight_strategy", {"same", "milp", "greedy_logdet", "stability", "anms"},
                         &tight_strategy);
#define HERMES_READ(name, var)             \
  if (s) s = c.get(p + name, &var);
#define HERMES_READ_BOOL(name, var)        \
  if (s) s = readOnOff(c, p + name, &var);
  HERMES_READ_BOOL("coordinator", coordinator)
  HERMES_READ("fixed_k", fixed_k)
  HERMES_READ("eta", eta)
  HERMES_READ("k_max", k_max)
  HERMES_READ("loop_keypoints", loop_keypoints)
  HERMES_READ("k_min", k_min)
  HERMES_READ("k_pref", k_pref)
  HERMES_READ("min_keyframe_rate_hz", min_keyframe_rate_hz)
  HERMES_READ("max_rounds", max_rounds)
  HERMES_READ("plan_fill", plan_fill)
  HERMES_READ("fill_accept", fill_accept)
  HERMES_READ("max_keyframes", max_keyframes)
  HERMES_READ("delta", delta)
  HERMES_READ_BOOL("adaptive_weights", adaptive_weights)
  HERMES_READ("alpha", alpha)
  HERMES_READ("beta", beta)
  HERMES_READ("alpha_per_loop", alpha_per_loop)
  HERMES_READ("beta_per_rad", beta_per_rad)
  HERMES_READ("future_poses", future_poses)
  HERMES_READ("future_horizon_s", future_horizon_s)
  HERMES_READ("epsilon", epsilon)
  HERMES_READ("lambda_support", lambda_support)
  HERMES_READ("lambda_grid", lambda_grid)
  HERMES_READ("grid_cols", grid_cols)
  HERMES_READ("grid_rows", grid_rows)
  HERMES_READ("milp_time_limit_s", milp_time_limit_s)
  HERMES_READ("milp_rel_gap", milp_rel_gap)
  HERMES_READ_BOOL("milp_warm_start", milp_warm_start)
  HERMES_READ("trim_w_rot", trim_w_rot)
  HERMES_READ("trim_w_trans", trim_w_trans)
  HERMES_READ("trim_lambda", trim_lambda)
  HERMES_READ("trim_min_shared", trim_min_shared)
  HERMES_READ("trim_time_limit_s", trim_time_limit_s)
  if (s) s = c.getChoice(p + "solver_limits", {"auto", "time", "work"}, &solver_limits);
  HERMES_READ("milp_max_nodes", milp_max_nodes)
  HERMES_READ("trim_max_nodes", trim_max_nodes)
  HERMES_READ("trim_max_lp_iterations", trim_max_lp_iterations)
  HERMES_READ_BOOL("trouble_aware", trouble_aware)
  HERMES_READ_BOOL("unplaced_aware", unplaced_aware)
  HERMES_READ("trouble_weak_frames", trouble_weak_frames)
  HERMES_READ("trouble_max_keyframes", trouble_max_keyframes)
  HERMES_READ("trouble_budget_gain", trouble_budget_gain)
  HERMES_READ("motion_keyframe_spacing", motion_keyframe_spacing)
  HERMES_READ("tracked_keyframe_fraction", tracked_keyframe_fraction)
  HERMES_READ("bytes_c0", bytes_c0)
  HERMES_READ("bytes_kf", bytes_kf)
  HERMES_READ("bytes_obs", bytes_obs)
  HERMES_READ("bytes_lm", bytes_lm)
#undef HERMES_READ
#undef HERMES_READ_BOOL
  if (!s) return s;
  Status v = validate();
  if (!v) return Error{"config " + c.origin() + ": " + v.error()};
  return Status::Ok();
}

Status DistillParams::validate() const {
  auto bad = [](const std::string& what) { return Status(Error{"distill." + what}); };
  if (fixed_k < 1) return bad("fixed_k must be >= 1");
  if (!(eta > 0 && eta <= 1)) return bad("eta must be in (0, 1]");
  if (!(window_s > 0)) return bad("window_s (window.period_s) must be > 0");
  if (k_min < 1 || k_max < k_min) return bad("k_min/k_max need 1 <= k_min <= k_max");
  if (loop_keypoints < 0) return bad("loop_keypoints must be >= 0");
  if (min_keyframe_rate_hz < 0) return bad("min_keyframe_rate_hz must be >= 0");
  if (max_rounds < 1 || max_rounds > 3) return bad("max_rounds must be in [1, 3]");
  if (!(fill_accept > 0 && fill_accept <= plan_fill && plan_fill <= 1))
    return bad("plan_fill/fill_accept need 0 < fill_accept <= plan_fill <= 1");
  if (max_keyframes < 2) return bad("max_keyframes must be >= 2");
  if (trouble_weak_frames < 1) return bad("trouble_weak_frames must be >= 1");
  if (!(motion_keyframe_spacing >= 0) || !std::isfinite(motion_keyframe_spacing))
    return bad("motion_keyframe_spacing must be >= 0 (0 = off)");
  if (!(tracked_keyframe_fraction >= 0 && tracked_keyframe_fraction <= 1))
    return bad("tracked_keyframe_fraction must be in [0, 1] (0 = off)");
  if (trouble_max_keyframes < max_keyframes)
    return bad("trouble_max_keyframes must be >= max_keyframes");
  if (!(trouble_budget_gain >= 1)) return bad("trouble_budget_gain must be >= 1");
  if (!(delta > 0)) return bad("delta must be > 0");
  if (alpha < 0 || beta < 0 || alpha + beta <= 0) return bad("alpha, beta must be >= 0, not both 0");
  if (alpha_per_loop < 0 || beta_per_rad < 0) return bad("alpha_per_loop/beta_per_rad must be >= 0");
  if (future_poses < 0 || future_horizon_s < 0) return bad("future_poses/horizon must be >= 0");
  if (!(epsilon > 0)) return bad("epsilon must be > 0");
  if (lambda_support < 0 || lambda_grid < 0) return bad("lambdas must be >= 0");
  if (grid_cols < 1 || grid_rows < 1) return bad("grid_cols/grid_rows must be >= 1");
  if (milp_rel_gap < 0 || milp_rel_gap >= 1) return bad("milp_rel_gap must be in [0, 1)");
  if (!(milp_time_limit_s > 0) || !(trim_time_limit_s > 0)) return bad("time limits must be > 0");
  if (solver_limits != "auto" && solver_limits != "time" && solver_limits != "work")
    return bad("solver_limits must be auto, time or work, got '" + solver_limits + "'");
  if (milp_max_nodes < 1 || trim_max_nodes < 1 || trim_max_lp_iterations < 1)
    return bad("milp_max_nodes, trim_max_nodes, trim_max_lp_iterations must be >= 1");
  if (trim_w_rot < 0 || trim_w_trans < 0) return bad("trim weights must be >= 0");
  if (trim_lambda < 0 || trim_min_shared < 1) return bad("trim_lambda >= 0, trim_min_shared >= 1");
  if (bytes_c0 < 0 || bytes_kf < 0 || !(bytes_obs > 0) || !(bytes_lm > 0))
    return bad("byte model: c0, kf >= 0 and obs, lm > 0");
  return Status::Ok();
}

void DistillParams::write(ConfigWriter* out) const {
  const std::string p = kPrefix;
  out->set(p + "strategy", strategy);
  out->set(p + "tight_strategy", tight_strategy);
  out->set(p + "coordinator", std::string(coordinator ? "on" : "off"));
  out->set(p + "fixed_k", fixed_k);
  out->set(p + "eta", eta);
  out->set(p + "k_max", k_max);
  out->set(p + "loop_keypoints", loop_keypoints);
  out->set(p + "k_min", k_min);
  out->set(p + "k_pref", k_pref);
  out->set(p + "min_keyframe_rate_hz", min_keyframe_rate_hz);
  out->set(p + "max_rounds", max_rounds);
  out->set(p + "plan_fill", plan_fill);
  out->set(p + "fill_accept", fill_accept);
  out->set(p + "max_keyframes", max_keyframes);
  out->set(p + "delta", delta);
  out->set(p + "adaptive_weights", adaptive_weights);
  out->set(p + "alpha", alpha);
  out->set(p + "beta", beta);
  out->set(p + "alpha_per_loop", alpha_per_loop);
  out->set(p + "beta_per_rad", beta_per_rad);
  out->set(p + "future_poses", future_poses);
  out->set(p + "future_horizon_s", future_horizon_s);
  out->set(p + "epsilon", epsilon);
  out->set(p + "lambda_support", lambda_support);
  out->set(p + "lambda_grid", lambda_grid);
  out->set(p + "grid_cols", grid_cols);
  out->set(p + "grid_rows", grid_rows);
  out->set(p + "milp_time_limit_s", milp_time_limit_s);
  out->set(p + "milp_rel_gap", milp_rel_gap);
  out->set(p + "milp_warm_start", milp_warm_start);
  out->set(p + "trouble_aware", std::string(trouble_aware ? "on" : "off"));
  out->set(p + "unplaced_aware", std::string(unplaced_aware ? "on" : "off"));
  out->set(p + "trouble_weak_frames", trouble_weak_frames);
  out->set(p + "trouble_max_keyframes", trouble_max_keyframes);
  out->set(p + "trouble_budget_gain", trouble_budget_gain);
  out->set(p + "motion_keyframe_spacing", motion_keyframe_spacing);
  out->set(p + "tracked_keyframe_fraction", tracked_keyframe_fraction);
  out->set(p + "trim_w_rot", trim_w_rot);
  out->set(p + "trim_w_trans", trim_w_trans);
  out->set(p + "trim_lambda", trim_lambda);
  out->set(p + "trim_min_shared", trim_min_shared);
  out->set(p + "trim_time_limit_s", trim_time_limit_s);
  out->set(p + "solver_limits", solver_limits);
  out->set(p + "milp_max_nodes", milp_max_nodes);
  out->set(p + "trim_max_nodes", trim_max_nodes);
  out->set(p + "trim_max_lp_iterations", trim_max_lp_iterations);
  out->set(p + "bytes_c0", bytes_c0);
  out->set(p + "bytes_kf", bytes_kf);
  out->set(p + "bytes_obs", bytes_obs);
  out->set(p + "bytes_lm", bytes_lm);
}

}  // namespace distill
}  // namespace hermes
