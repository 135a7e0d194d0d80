// The whole system in one process (DESIGN §8, `hermes run`): N agents, each
// feeding its dataset into an AgentPipeline whose uplink crosses one emulated
// shared bottleneck (SharedLink) to the edge server (server::Server), all on a
// simulated clock that starts at 0 for every agent's first frame. Deterministic:
// the only randomness is the link's seeded loss draws.
//
// Data flow, per clock step (ClockParams::step_s):
//   link.advanceTo(t) -> delivered frames -> Server::onFrame -> ack over the link
//   acks due -> AgentPipeline::onAck (frees the spool, feeds the bandwidth monitor)
//   frames due (in time order over agents) -> AgentPipeline::feed -> windows ->
//     distill (budget from the monitor) -> encode -> spool -> transport -> link.send
//   every server_period_s: Server::process (credibility order, merge, loops, graph)
// After the last frame the link runs on for at most drain_s so the backlog arrives.
#pragma once

#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "hermes/agent/agent_pipeline.h"
#include "hermes/core/bandwidth_log.h"
#include "hermes/core/dataset.h"
#include "hermes/core/emulated_link.h"
#include "hermes/system/system_params.h"

namespace hermes::system {

struct AgentSource {
  std::string name;                  ///< unique, no commas (CSV)
  std::unique_ptr<Dataset> dataset;
  std::size_t max_frames = 0;        ///< 0 = all
};

struct OfflineAgent {
  std::string name;
  std::unique_ptr<Dataset> dataset;
  std::unique_ptr<agent::AgentPipeline> pipeline;
  std::size_t frames = 0, next = 0;  ///< frames to feed, next index
  double clock_offset = 0;           ///< dataset stamp of frame 0 (sim t = stamp - offset)
  std::optional<RobotId> robot;      ///< server robot id once a submap was accepted
  std::size_t acked = 0, lost_messages = 0;
  double next_retry = 0;  ///< [s] after the last frame: next try of a deferred window
};

struct ProgressInfo {
  double sim_time = 0, sim_end = 0;  ///< [s]
  std::size_t frames_done = 0, frames_total = 0;
  int merged_submaps = 0, agents_merged = 0;
  bool draining = false;
};

class OfflineRun {
 public:
  /// Opens nothing itself: the datasets are given. `spool_root`: each agent's spool
  /// folder is spool_root/<name> (emptied first: a run starts fresh). `base_dir`
  /// resolves the server's vocabulary path.
  static Expected<std::unique_ptr<OfflineRun>> create(const SystemParams& params,
                                                      std::vector<AgentSource> agents,
                                                      const std::string& spool_root,
                                                      const std::string& base_dir);

  /// Runs to the end (all frames fed, backlog delivered or drain_s over).
  /// `progress` is called about every simulated second. Errors: a frame fails to
  /// load or a pipeline rejects it (names agent and frame).
  Status run(const std::function<void(const ProgressInfo&)>& progress = nullptr);

  const std::vector<OfflineAgent>& agents() const { return agents_; }
  const server::Server& server() const { return *server_; }
  /// For test/bench hooks (MapManager::setCandidateHook) before run().
  server::Server& server() { return *server_; }
  const SharedLink& link() const { return *link_; }
  const std::vector<BandwidthSample>& bandwidth() const { return bandwidth_; }
  /// Per agent: (sim time, bandwidth estimate [B/s]) at each bandwidth sample.
  const std::map<std::string, std::vector<std::pair<double, double>>>& estimates() const {
    return estimates_;
  }
  double simTime() const { return now_; }
  /// Frames delivered to the server but lost on the way (link loss), all agents.
  std::size_t lostMessages() const;
  const SystemParams& params() const { return params_; }

 private:
  OfflineRun(SystemParams params, std::unique_ptr<server::Server> server);
  Status feedDueFrames(double t);
  void deliver(double t);
  void acknowledge(double t);
  void sample(double t);
  /// Agents past their last frame try their deferred window again (one per period).
  void retryCarriedWindows(double t);

  struct PendingAck {
    double time;
    std::size_t agent;
    std::uint32_t session;
    std::uint64_t seq;
  };
  struct MessageKey {
    std::size_t agent;
    std::uint32_t session;
    std::uint64_t seq;
  };

  SystemParams params_;
  std::unique_ptr<SharedLink> link_;
  std::unique_ptr<server::Server> server_;
  std::vector<OfflineAgent> agents_;
  std::map<std::uint64_t, MessageKey> messages_;  ///< link message id -> submap
  std::uint64_t next_message_ = 0;
  std::vector<PendingAck> acks_;                  ///< sorted by time on use
  std::vector<BandwidthSample> bandwidth_;
  std::map<std::string, std::vector<std::pair<double, double>>> estimates_;
  std::vector<std::size_t> last_transmitted_;
  double now_ = 0, next_sample_ = 0, next_server_ = 0;
};

}  // namespace hermes::system
