// Parameters of the map distillation (section `distill.` of the configuration).
//
// Keys (units in brackets):
//   distill.strategy          milp | greedy_logdet | stability | anms | none
//                             (none = raw streaming: every keyframe and landmark of
//                             the window, no trimming, no budget)
//   distill.tight_strategy    selection where the link binds: the budget holds K below
//                             k_max, or the landmarks are all a measured link gets from
//                             the window (a backlog, or the plan leaves no room for loop
//                             keypoints): milp | greedy_logdet | stability | anms | same
//                             (= distill.strategy); coordinator on only
//   distill.coordinator       on | off  (a YAML bool true/false is accepted as well);
//                             off = fixed K (distill.fixed_k), all keyframes up to
//                             distill.max_keyframes, no byte budget
//   distill.fixed_k           landmarks kept per keyframe when the coordinator is off
//   distill.eta               safety factor on the bandwidth budget [-]
//   distill.delta             δ of q_a and f(S) [-]
//   distill.epsilon           ε of Eq. 14 [-]
//   distill.lambda_support    λ₁ (per missing landmark of a keyframe's support)
//   distill.lambda_grid       λ₂ (per uncovered occupied image cell)
//   distill.grid_cols, distill.grid_rows   image grid of the coverage constraint
//   distill.milp_time_limit_s CBC time limit per window, shared by its rounds [s]
//   distill.milp_rel_gap      relative optimality gap at which CBC stops (0 = exact)
//   distill.milp_warm_start   warm start CBC from the greedy solution [bool]
//   distill.alpha, distill.beta   fixed score weights (used when adaptive_weights off)
//   distill.adaptive_weights  α grows with loop closures, β with inter-KF rotation [bool]
//   distill.alpha_per_loop    α gain per loop closure (saturating at 10 loops)
//   distill.beta_per_rad      β gain per radian of mean inter-keyframe rotation
//   distill.future_poses      number of predicted poses of the motion attention
//   distill.future_horizon_s  horizon of the constant-velocity prediction [s]
//   distill.trim_w_rot, distill.trim_w_trans  sd() weights [1/rad], [1/m]
//   distill.trim_lambda       λ of Eq. 15 (per missing landmark observation)
//   distill.trim_min_shared   landmarks two consecutive kept keyframes must share
//   distill.trim_time_limit_s CBC time limit of the trimming MILP [s]
//   distill.solver_limits     auto | time | work: what stops the two MILPs. time (a
//                             robot): the wall-clock limits above, so a loaded CPU
//                             gets a worse selection, never a late one. work:
//                             deterministic work limits instead, no clock read, so
//                             a run gives the same submaps on any machine and load.
//                             auto: work in the offline runner (it resolves it,
//                             SystemParams::offlineAgent), time everywhere else.
//                             The work limits:
//   distill.milp_max_nodes    CBC branch-and-bound nodes per selection
//   distill.trim_max_nodes    CBC nodes of the trimming MILP
//   distill.trim_max_lp_iterations  Clp iterations of the trimming MILP's root LP
//   distill.max_keyframes     N_KF when the coordinator is off
//   distill.trouble_*         windows where tracking was lost or weak (see below)
//   distill.k_max, distill.k_min   range of K the coordinator may choose
//   distill.k_pref            K the coordinator keeps before it drops keyframes
//   distill.loop_keypoints    most keypoints per kept keyframe sent without a
//                             landmark (descriptor + depth, for the server's loop
//                             closure) once K = k_max leaves budget over on a link
//                             that keeps up (at most half the budget); 0 = none
//   distill.min_keyframe_rate_hz   floor: fewer kept keyframes per second -> defer
//   distill.max_rounds        encode/shrink rounds (<= 3)
//   distill.plan_fill         fraction of the budget S the planned (N_KF, K) is
//                             predicted to use [-] (< 1 keeps the selector's hard
//                             budget from binding as often)
//   distill.fill_accept       a fitting selection at or above this fraction of S is
//                             kept; below it (and K < k_max) K grows for another round [-]
//   distill.bytes_c0, bytes_kf, bytes_obs, bytes_lm   initial byte model [B]
// Not keys of this section: the period Δt (window_s) is the agent's window.period_s
// (AgentPipelineParams sets it), and probing for more bandwidth is the bandwidth
// monitor's (uplink.monitor.probe_factor scales the rate the budget is planned with).
#pragma once

#include <string>

#include "hermes/core/config.h"
#include "hermes/core/status.h"

namespace hermes {
namespace distill {

struct DistillParams {
  std::string strategy = "milp";
  std::string tight_strategy = "anms";
  bool coordinator = true;
  int fixed_k = 60;

  // Coordinator (Eq. 17).
  double eta = 0.8;
  /// Δt [s]: set from window.period_s by the agent (not read from distill.*).
  double window_s = 5.0;
  int k_max = 150;
  int loop_keypoints = 400;
  int k_min = 15;
  int k_pref = 60;
  double min_keyframe_rate_hz = 0.4;
  int max_rounds = 3;
  double plan_fill = 1.0;
  double fill_accept = 0.8;
  int max_keyframes = 12;

  // Scores.
  double delta = 1e-3;
  bool adaptive_weights = true;
  double alpha = 0.5;
  double beta = 0.5;
  double alpha_per_loop = 0.2;
  double beta_per_rad = 4.0;
  int future_poses = 3;
  double future_horizon_s = 1.0;

  // Landmark selection (Eq. 14).
  double epsilon = 0.05;
  double lambda_support = 2.0;
  double lambda_grid = 1.5;
  int grid_cols = 12;  // 6 x 4 -> 12 x 8: README "Seventeenth pass"
  int grid_rows = 8;
  double milp_time_limit_s = 0.1;
  double milp_rel_gap = 1e-3;
  bool milp_warm_start = true;

  // Keyframe trimming (Eq. 15-16).
  double trim_w_rot = 1.0 / 0.1745;  // 10 deg of rotation weigh as much as ...
  double trim_w_trans = 1.0 / 0.5;   // ... 0.5 m of translation
  double trim_lambda = 0.05;
  int trim_min_shared = 10;
  double trim_time_limit_s = 0.05;
  // What stops the MILPs (see the key list above); auto = time unless resolved.
  std::string solver_limits = "auto";
  int milp_max_nodes = 10;
  int trim_max_nodes = 10;
  int trim_max_lp_iterations = 1500;
  bool workLimits() const { return solver_limits == "work"; }

  // Windows in trouble (issue 16 item 4): the agent's tracking was lost, or
  // weak on at least trouble_weak_frames frames, within the window (or a kept
  // keyframe follows a loss). Such a window keeps up to trouble_max_keyframes
  // keyframes (the server needs them and their landmarks there to repair the
  // odometry with loops) and plans with trouble_budget_gain x the link's share
  // of Eq. 17. A gain above 1 borrows: the extra bytes enter the backlog and the
  // sound windows after it get less (Eq. 17 subtracts the backlog); on a tight
  // link that can starve the next window (a 10-s lossy 2 Mbit/s run: a robot
  // ended with 9 keyframes instead of 16), so the default is 1.
  bool trouble_aware = true;
  // A robot the server has not placed in the global map yet (no global pose
  // back, CoordinatorInput::placed) keeps up to trouble_max_keyframes per window
  // too, within the same budget: with 12 keyframes a window, two groups of a
  // 10-robot swarm never closed a loop between them (5/10 merged).
  bool unplaced_aware = true;
  int trouble_weak_frames = 3;
  int trouble_max_keyframes = 24;
  double trouble_budget_gain = 1.0;
  // A window that moves far keeps up to one keyframe per motion_keyframe_spacing
  // of motion (the trimming's separation units: trim_w_trans per metre plus
  // trim_w_rot per radian, 1 = 0.5 m or ~10 deg), between max_keyframes and
  // trouble_max_keyframes (surplusKeyframeCap), with the coordinator on (fixed K
  // keeps max_keyframes). The fast robots' keyframes are
  // the ones raw streaming's extra loops stand on (whole MH, unlimited: 12
  // keyframes a window 0.74 cm / 40.7 MB, 1.5 -> 0.67 cm / 42.8 MB; 1.0 ->
  // 0.69 / 48.8; 16 for every window 0.68 / 50.0). 1.5 -> 1.25 with three place
  // candidates per keyframe on the server: 10 Mbit/s 0.69 -> 0.65 cm, 42.3 ->
  // 44.6 MB (1.07x raw streaming at 32 % of its bytes; README sixteenth pass). 0 = off.
  double motion_keyframe_spacing = 1.25;
  // ... and up to this fraction of the keyframes its tracker made (each one a
  // view change the covisibility rule saw), in the same bounds and from the same
  // surplus: near landmarks (a small room) change the view faster than the motion
  // measure says. 0 = off.
  double tracked_keyframe_fraction = 0.55;

  // Initial byte model.
  double bytes_c0 = 256;
  double bytes_kf = 120;
  double bytes_obs = 44;
  double bytes_lm = 64;

  /// Reads every key under `distill.` (window_s is not one); missing keys keep their defaults.
  Status read(const Config& config);
  Status validate() const;
  void write(ConfigWriter* out) const;
};

}  // namespace distill
}  // namespace hermes
