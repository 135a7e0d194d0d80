// Configuration of a whole-system run (hermes_run): the agent pipeline, dataset
// reading and evaluation (agent::RunParams), the edge server (section server),
// and the emulated network plus the runner's own clock (section link, system);
// the ROS nodes' transport (transport, mqtt) is checked too.
// Read from one Config; a key no module reads is an error.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "hermes/agent/odometry_corruption.h"
#include "hermes/agent/relay_split.h"
#include "hermes/agent/run_config.h"
#include "hermes/core/config.h"
#include "hermes/core/link_trace.h"
#include "hermes/server/server.h"
#include "hermes/transport/transport_params.h"

namespace hermes::system {

/// The shared bottleneck all agents' uplinks cross (the server's downlink).
struct LinkParams {
  double bandwidth_mbitps = 0;   ///< [Mbit/s] constant shared rate; 0 = unlimited
  double latency_ms = 20;        ///< [ms] one-way latency (constant links)
  double loss = 0;               ///< message loss probability in [0, 1) (constant links)
  std::string trace;             ///< CSV trace file (link_trace.h); overrides the three above
  /// Scenario file (scenario.h): a link per robot to the server and between
  /// robots, instead of the one shared link; overrides everything above but
  /// packet_bytes and seed.
  std::string scenario;
  int packet_bytes = 1500;       ///< [B] round-robin service unit between agents
  int seed = 1;                  ///< loss draws

  Status read(const Config& config);
  Status validate() const;
  void write(ConfigWriter& out) const;
  /// The trace in force: the file when `trace` is set, else a constant link.
  Expected<LinkTrace> makeTrace() const;
};

/// A robot that restarts or resets its map at `at_s` (system.agent_reset).
struct AgentReset {
  std::string agent;  ///< the agent's name
  double at_s = 0;    ///< [s] simulated time
  bool operator==(const AgentReset& o) const { return agent == o.agent && at_s == o.at_s; }
};
/// "NAME@S[,NAME@S ...]" (spaces around items allowed; empty: none). Errors name
/// the item that is not NAME@S with S a finite time >= 0.
Expected<std::vector<AgentReset>> parseAgentResets(const std::string& spec);
std::string formatAgentResets(const std::vector<AgentReset>& resets);

/// The runner's simulated clock.
struct ClockParams {
  double step_s = 0.01;          ///< [s] network/ack event resolution
  double server_period_s = 0.5;  ///< [s] the server merges its queue this often
  double sample_period_s = 1.0;  ///< [s] bandwidth CSV interval
  double drain_s = 60;           ///< [s] after the last frame, time allowed to deliver the rest
  /// [s] the server's health (memory, queue, time per submap) is sampled this
  /// often (OfflineRun::health(), health.csv; a soak's plots); 0 = never.
  double health_period_s = 0;
  /// Agents fed side by side within a clock step (offline_run.h); 1 = one after
  /// another. The results do not depend on it.
  int agent_threads = 2;
  /// [s] simulated times at which the server object is destroyed without a
  /// clean shutdown and, server_downtime_s later, created again from its
  /// checkpoint directory (`hermes run --server-restart-at S`).
  std::vector<double> server_restart_at;
  double server_downtime_s = 1.0;  ///< [s] no server between destruction and re-creation
  /// system.agent_reset ("NAME@S, ...", `hermes run --agent-reset NAME@S`): at
  /// simulated time S the agent's pipeline is destroyed as in a crash (its open
  /// window is lost) and created again with a fresh map and the next session,
  /// going on from the dataset frame due at S (offline_run.h).
  std::vector<AgentReset> agent_reset;
  /// Tracking record / replay (tracking_record.h; `hermes run --record-tracking
  /// DIR` / `--replay-tracking DIR`): every agent's tracking is written to /
  /// read from DIR/<agent>.htrk; replay tracks no image. Both set: each agent
  /// replays when its recording in the replay dir fits this run, else it is
  /// tracked and recorded (trackingMode). Empty: off. Not with agent_reset or
  /// agent.parallel.
  std::string tracking_record_dir, tracking_replay_dir;

  Status read(const Config& config);
  Status validate() const;
  void write(ConfigWriter& out) const;
};

struct SystemParams {
  agent::RunParams run;           ///< agent pipeline, dataset, eval
  server::ServerParams server;    ///< section server
  LinkParams link;                ///< section link
  agent::RelayParams relay;       ///< section relay (scenario runs)
  ClockParams clock;              ///< section system
  agent::OdometryCorruptionParams corrupt;  ///< section corrupt (test hook)
  /// Keys transport, mqtt: read by the ROS nodes; checked here, unused by the
  /// offline runner (its agents always talk over the emulated link).
  transport::TransportParams transport;

  Status read(const Config& config);
  /// Every module's validate(), then the keys that must agree across modules.
  Status validate() const;
  /// Every key with its value (what yaml() holds).
  void write(ConfigWriter& out) const;
  /// The YAML written as OUT/config_used.yaml (reads back to the same params).
  std::string yaml() const;
  /// The agent pipeline as the offline runner runs it: distill.solver_limits
  /// auto becomes work (deterministic: the same result on any machine load).
  agent::AgentPipelineParams offlineAgent() const;
};

/// Reads SystemParams and fails when a key was read by no module (the message
/// lists the unknown keys and the config origin).
Expected<SystemParams> readSystemParams(const Config& config);

}  // namespace hermes::system
