// Results of a whole-system run (DESIGN §7): evaluation against each dataset's
// ground truth and the results folder.
//   OUT/config_used.yaml                  (written by the caller, before the run)
//   OUT/metrics.json                      DESIGN §7 contract + extras
//   OUT/trajectories/<agent>_raw.tum      the agent's own odometry (body, odometry frame)
//   OUT/trajectories/<agent>_merged.tum   its keyframes in the server's world frame (body)
//   OUT/bandwidth.csv                     time_s,agent,kBps,link_capacity_kBps
//   OUT/uplink_estimate.csv               time_s,agent,estimate_kBps (the agents' monitors)
//   OUT/ate_over_time.csv                 time_s,agent,error_m (merged, common alignment)
//   OUT/health.csv                        the server's health over time (system.health_period_s > 0)
//   OUT/loops.csv                         accepted loops with their error against ground truth
//   OUT/pose_graph_edges.csv              the last pose-graph solve, edge by edge
//   OUT/pose_graph.g2o, pose_graph_nodes.csv   that graph (g2o text) and its nodes'
//                                         agents, stamps and ground truth (bench pose_graph)
//   OUT/global_map.ply                    landmarks of the merged map (world frame)
#pragma once

#include <map>
#include <optional>
#include <string>

#include <nlohmann/json_fwd.hpp>
#include <vector>

#include "hermes/core/metrics.h"
#include "hermes/system/durability_report.h"
#include "hermes/system/offline_run.h"
#include "hermes/system/relay_report.h"

namespace hermes::system {

/// Accuracy of the accepted inter-/intra-agent loops against ground truth.
struct LoopAccuracy {
  std::size_t loops = 0;            ///< accepted loops whose keyframes have ground truth
  std::size_t inter_agent = 0;
  double median_trans_m = 0, median_rot_deg = 0;
  double p95_trans_m = 0, max_trans_m = 0;
  std::size_t wrong = 0;            ///< accepted loops off by > 0.1 m or > 2 deg (false loops)
};

/// What merging gave: the one map the robots were placed in (the report's lead,
/// metrics.json "global_map").
struct MapSummary {
  std::int64_t robots = 0;             ///< robots of this run placed in the map's one world frame
  std::int64_t prior_robots = 0;       ///< robots of the prior map the server started on (server.prior_map)
  std::int64_t keyframes = 0, landmarks = 0;
  std::int64_t loops_inter_robot = 0;  ///< accepted loops between two different robots
  double path_m = 0;                   ///< every placed robot's keyframe path in the map, summed [m]
  std::map<std::string, double> robot_path_m;  ///< each placed robot's keyframe path [m]
  /// Sides of the box around every keyframe position, along their principal axes,
  /// longest first [m].
  Vec3 extent_m = Vec3::Zero();
};

struct RunResults {
  RunMetrics metrics;
  MapSummary map;
  /// Bytes of the images the robots' cameras took over the run, uncompressed (8-bit
  /// grey stereo pairs; RGB + 16-bit depth): what streaming the cameras would send
  /// (metrics.json "camera_bytes_total").
  std::int64_t camera_bytes = 0;
  /// Bytes raw streaming of the same windows would have sent: every window the
  /// robots cut, encoded whole (WindowCounters::window_bytes; metrics.json
  /// "raw_streaming_bytes_total").
  std::int64_t raw_streaming_bytes = 0;
  std::optional<LoopAccuracy> loop_accuracy;
  std::map<std::string, std::size_t> loops_per_pair;  ///< "a-b" -> accepted loops
  std::vector<std::string> warnings;                  ///< e.g. an agent that could not be evaluated
  std::optional<DurabilitySummary> durability;        ///< with a server checkpoint directory
  std::optional<RelaySummary> relay;                  ///< with a scenario (link.scenario)
};

/// Evaluates the finished run and fills the metrics (no files).
RunResults evaluateRun(const OfflineRun& run);

/// metrics.json: the DESIGN §7 metrics plus "global_map", "camera_bytes_total",
/// "raw_streaming_bytes_total",
/// "loop_accuracy", "loops_per_pair", "warnings",
/// and with checkpoints "server_durability" and "server_restarts" (durability_report.h).
nlohmann::json resultsJson(const RunResults& results);

/// The server's final state as a checkpoint in `dir` (emptied first): what a
/// later run resumes on (--prior-map DIR, server.prior_map).
Status saveMapToResume(const server::Server& server, const std::string& dir);

/// Writes every file listed above except config_used.yaml. Errors name the file.
Status writeRunResults(const OfflineRun& run, const RunResults& results, const std::string& out_dir);

/// Every loop-closure attempt of a run (MapManager::setAttemptHook) as CSV:
/// query and candidate (agent, keyframe, stamp), place scores, verdict, reason,
/// matches, inliers, and the true distance [m] and angle [deg] between the two
/// camera poses (empty without ground truth). Shows which revisits the place
/// recognition never proposed and which the geometry refused.
Status writeLoopAttempts(const OfflineRun& run, const std::vector<server::LoopAttempt>& attempts,
                         const std::string& path);

/// A short human-readable report. It leads with what merging gave: robots placed in
/// one map, the map (keyframes, landmarks, metres flown, extent), loops between robots,
/// bytes sent against the cameras' images, and per robot its odometry ATE (own frame)
/// beside its merged ATE (the one map); then the details (lost, submaps, kB, own world
/// pose, loop accuracy).
std::string formatReport(const OfflineRun& run, const RunResults& results);

}  // namespace hermes::system
