// Run metrics (DESIGN §7 metrics JSON contract), their JSON form, and a small
// per-stage timing accumulator.
//
// JSON policy: every contract key (ate_rmse_m, per_agent, bytes_total, kBps_mean,
// kBps_peak, loops_accepted, loops_rejected, agents_merged, timings_ms, and inside
// each per_agent entry: agent, ate_rmse_m, lost_rate, keyframes, landmarks, bytes,
// submaps_sent, submaps_applied, submaps_deferred) is ALWAYS written; a value that
// does not apply to the run (e.g. loops without a server) is `null`. per_agent is a
// list (possibly empty), timings_ms an object {stage: {median, p95, count}} (possibly
// empty). Extra keys (ate, rpe, alignment, matched poses, ...) are OMITTED when they
// do not apply. Reading requires every contract key (null allowed) and accepts
// missing extras. kB = 1000 bytes.
#pragma once

#include <cstdint>
#include <map>
#include <nlohmann/json_fwd.hpp>
#include <optional>
#include <string>
#include <vector>

#include "hermes/core/evaluation.h"

namespace hermes {

/// Summary of one stage's timings [ms].
struct StageTiming {
  double median = 0;
  double p95 = 0;
  int64_t count = 0;
};

/// Collects durations per stage. Not thread-safe: keep one per thread and merge().
///
/// By default every sample is kept (offline runs: exact statistics over the run).
/// With a window of W > 0 samples per stage (a live process that runs for hours
/// and summarises often), median and p95 are over the stage's last W samples and
/// memory stays below 2 W samples per stage; count is still every sample added.
class TimingStats {
 public:
  explicit TimingStats(size_t window = 0) : window_(window) {}
  void add(const std::string& stage, double ms);
  void merge(const TimingStats& other);
  /// Median (mean of the two middle values for even counts) and p95 (linear
  /// interpolation between closest ranks, like numpy's default); count = all added.
  std::map<std::string, StageTiming> summary() const;
  size_t count(const std::string& stage) const;
  size_t window() const { return window_; }
  /// The samples kept per stage, in the order added (all of them without a
  /// window; checkpoints keep them).
  const std::map<std::string, std::vector<double>>& samples() const { return samples_; }

 private:
  void trim(const std::string& stage);

  size_t window_ = 0;
  std::map<std::string, std::vector<double>> samples_;
  std::map<std::string, size_t> dropped_;  ///< samples trimmed away per stage (window only)
};

namespace timing {
/// Linear-interpolated percentile q in [0, 100] of values (0 when empty). In its own
/// namespace so that `using namespace hermes` does not clash with local helpers.
double percentile(std::vector<double> values, double q);
}  // namespace timing

/// Accuracy statistics written as extras ("ate": {...}, "rpe": {...}).
struct AccuracyStats {
  double rmse = 0, mean = 0, median = 0, max = 0, std = 0;
};

struct AgentMetrics {
  // Contract fields.
  std::string agent;
  std::optional<double> ate_rmse_m;
  std::optional<double> lost_rate;  ///< fraction of frames with tracking lost
  std::optional<int64_t> keyframes, landmarks, bytes;
  std::optional<int64_t> submaps_sent, submaps_applied, submaps_deferred;
  // Extras.
  std::optional<AccuracyStats> ate_m;           ///< "ate": own alignment
  std::optional<double> merged_ate_rmse_m;      ///< under the run's common alignment
  std::optional<double> raw_ate_rmse_m;         ///< the agent's own odometry, own alignment
  std::optional<double> rpe_trans_rmse_m, rpe_rot_rmse_deg;
  std::optional<int64_t> matched_poses, unmatched_poses;
  std::optional<double> scale;                  ///< sim3 only
  std::optional<int64_t> held_submaps;          ///< server: submaps waiting to be merged now
  std::optional<int64_t> held_bytes;            ///< server: their frame bytes now [B]
  std::optional<int64_t> held_bytes_peak;       ///< server: the most ever held at once [B]
  std::optional<int64_t> weak_frames;           ///< agent: frames tracked with few inliers
  std::optional<int64_t> trouble_windows;       ///< agent: windows distilled as in trouble
  /// What the robot knew of its own place in the world (server's world <- odom x
  /// its odometry), under the run's common alignment: RMSE over the frames since
  /// the first update, and the error at its last frame [m].
  std::optional<double> global_pose_rmse_m, global_pose_final_m;
  std::optional<int64_t> global_pose_updates;   ///< world <- odom updates it took
  /// Server: the robot's sessions (a restart or map reset starts one; every
  /// session keeps the robot's id and entry), of those the later ones verified
  /// loops tied to the global map (re-localised) and the ones no loop tied
  /// within server.relocalisation_timeout_s (reported as a new robot).
  std::optional<int64_t> sessions, relocalised, reported_new;
  /// Agent: frames that could not be read and were skipped, and by cause
  /// ("unreadable", "wrong_size", "wrong_format"); causes omitted when none.
  std::optional<int64_t> frames_skipped;
  /// Agent: new maps started after tracking was lost for tracker.reinit_after_s.
  std::optional<int64_t> new_maps;
  /// Agent: the borrowed map (the server's downlink): sessions it placed in
  /// the world by relocalisation, landmarks held at the end, their memory [B];
  /// and the downlink's bytes to this robot, resends included [B].
  std::optional<int64_t> borrowed_relocalisations, borrowed_landmarks, borrowed_memory_bytes;
  std::optional<int64_t> downlink_bytes;
  std::map<std::string, int64_t> frames_skipped_causes;
};

struct RunMetrics {
  // Contract fields.
  std::optional<double> ate_rmse_m;  ///< merged trajectory, one common alignment
  std::vector<AgentMetrics> per_agent;
  std::optional<int64_t> bytes_total;
  std::optional<double> kBps_mean, kBps_peak;
  std::optional<int64_t> loops_accepted, loops_rejected, agents_merged;
  std::map<std::string, StageTiming> timings_ms;
  // Extras.
  std::optional<std::string> alignment;  ///< "se3" | "sim3" | "first" | "none"
  std::optional<SE3> T_gt_est;           ///< the common alignment transform
  std::optional<double> scale;
  std::optional<AccuracyStats> ate_m;    ///< merged
  std::optional<int64_t> matched_poses, unmatched_poses;
  std::optional<double> max_dt_s, rpe_delta;
  std::optional<std::string> rpe_delta_unit;  ///< "s" | "frames"
  /// Server: frames not accepted, by reason ("bad_tag", "quota", ...); omitted when none.
  std::map<std::string, int64_t> frames_refused;
  /// Server: sessions re-localised / reported as new robots, over all robots
  /// (per_agent relocalised / reported_new summed).
  std::optional<int64_t> relocalised, robots_new;
  std::optional<int64_t> loops_bridged;  ///< of loops_accepted, bridging tie groups (group_bridge.h)
  /// Set when the run stopped before the end of its data (an error, Ctrl-C): the
  /// metrics cover what was tracked until then; `stopped_because` says why.
  std::optional<bool> incomplete;
  std::optional<std::string> stopped_because;
};

void to_json(nlohmann::json& j, const RunMetrics& m);
void to_json(nlohmann::json& j, const AgentMetrics& m);
/// Throws std::invalid_argument (message names the field) on bad input; prefer
/// metricsFromJson, which returns the error instead.
void from_json(const nlohmann::json& j, RunMetrics& m);

/// `source` (e.g. the file name) prefixes error messages.
Expected<RunMetrics> metricsFromJson(const nlohmann::json& j, const std::string& source);
std::string metricsToJsonString(const RunMetrics& m, int indent = 2);
Status writeMetricsJson(const std::string& path, const RunMetrics& m);
Expected<RunMetrics> readMetricsJson(const std::string& path);

/// Fills the accuracy fields (ate, per-agent ate/rpe, alignment) from an evaluation;
/// creates per_agent entries named after the evaluated agents when missing.
void fillAccuracy(const eval::MultiAgentEval& ev, const eval::EvalParams& params,
                  RunMetrics* m);

}  // namespace hermes
