// The whole system in one process (DESIGN §8, `hermes run`): N agents, each
// feeding its dataset into an AgentPipeline whose uplink crosses one emulated
// shared bottleneck (SharedLink) to the edge server (server::Server), all on a
// simulated clock that starts at 0 for every agent's first frame. Deterministic:
// the only randomness is the link's seeded loss draws, as long as no wall-clock
// limit binds. The distiller's CBC limits (distill.milp_time_limit_s 0.1 s,
// trim_time_limit_s 0.05 s by default) are wall-clock: two runs of whole V1 on a
// loaded machine (replaying one tracking recording) differed by ~0.1 % in bytes,
// ~1 % in loops and 0.59-0.62 cm in merged ATE, with the same odometry bit for bit.
//
// Data flow, per clock step (ClockParams::step_s):
//   link.advanceTo(t) -> delivered frames -> Server::onFrame -> ack over the link
//   acks due -> AgentPipeline::onAck (frees the spool, feeds the bandwidth monitor)
//   frames due (in time order over agents) -> AgentPipeline::feed -> windows ->
//     distill (budget from the monitor) -> encode -> spool -> transport -> link.send
//   every server_period_s: Server::process (credibility order, merge, loops, graph),
//     then the downlink (downlink_channel.h): packets of the map around each placed
//     robot over a link of their own -> AgentPipeline::onMapDown -> ack back
// After the last frame the link runs on for at most drain_s so the backlog arrives.
//
// Agents side by side (system.agent_threads): within one clock step the agents
// do not see each other (what one sends reaches the link, and so anyone, only
// when the link is advanced at the next step), so each agent's due frames are
// fed on a worker thread of its own and the submaps they hand to the transport
// are held and put on the link afterwards in the order one thread would have
// sent them (frame stamp, then agent index). Same results for any thread count.
//
// Tracking record / replay (system.tracking_record_dir / tracking_replay_dir,
// tracking_record.h): tracking does not depend on the link, the server or the
// distiller, so a run can write every agent's tracking to a file and a later
// run of the same sequences (any variant, any bandwidth) replays it instead of
// loading and tracking images: same frames on the same clock, the same window
// step from the recorded windows on. Same results as tracking live.
//
// Scenario runs (link.scenario, scenario.h): instead of the one shared link, a
// link per robot to the server and between robots (RelayNetwork): robots out of
// the server's reach hand their submaps to a relay robot (relay.*).
//
// Server restarts (system.server_restart_at): at each time the server object is
// destroyed as in a crash (no clean checkpoint), frames arriving while it is
// down are lost (never acknowledged), and server_downtime_s later it is created
// again from its checkpoint directory; the agents are told it is back
// (UplinkSender::onReconnect: resend everything unacknowledged) and the server
// drops what it had already accepted. Without server.checkpoint_dir the runner
// uses <spool_root>/../server_checkpoint; the directory is emptied when the run
// starts (a run starts fresh, like the spools), and the server writes a last
// checkpoint when the run ends.
//
// Agent resets (system.agent_reset, "NAME@S"): at S the agent's pipeline is
// destroyed as in a crash (its open window and map are lost) and created again
// over the same spool: a fresh map whose odometry starts at identity (it does
// not know its old pose) and the next session, fed from the dataset frame due
// at S. The spool's unacknowledged submaps of the old session are still sent
// and acknowledged; the server applies them unless they arrive more than
// server.bookkeeper.stale_after_s after the new session began (stale: only
// acknowledged). The server then re-localises the new session through loops
// or, after server.relocalisation_timeout_s, reports it as a new robot
// (bookkeeper.h); either way it keeps the robot's id.
#pragma once

#include <atomic>
#include <chrono>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "hermes/agent/agent_pipeline.h"
#include "hermes/agent/frame_skips.h"
#include "hermes/agent/tracking_log.h"
#include "hermes/core/bandwidth_log.h"
#include "hermes/core/dataset.h"
#include "hermes/core/emulated_link.h"
#include "hermes/system/downlink_channel.h"
#include "hermes/system/relay_network.h"
#include "hermes/system/system_params.h"

namespace hermes::system {

/// A take-off of a robot that flies several sorties (a mission, mission.h): from
/// dataset frame `first_frame` on it flies a new session with a fresh map; the
/// sortie before it landed at the frame before (its last window flushed, its
/// spool kept).
struct Sortie {
  std::size_t first_frame = 0;
  /// Replay (tracking_record.h): this sortie's tracking is the recording at
  /// `replay_path`, which must carry `replay_key` (the sequence the sortie
  /// flies), its stamps moved by `replay_shift_s` onto the dataset's; empty
  /// path: tracked live from the images.
  std::string replay_path;
  agent::TrackingKey replay_key;
  double replay_shift_s = 0;
};

struct AgentSource {
  AgentSource() = default;
  AgentSource(std::string n, std::unique_ptr<Dataset> d, std::size_t max = 0)
      : name(std::move(n)), dataset(std::move(d)), max_frames(max) {}

  std::string name;                  ///< unique, no commas (CSV)
  std::unique_ptr<Dataset> dataset;
  std::size_t max_frames = 0;        ///< 0 = all
  /// Several sorties (the first at frame 0), each set up here instead of by
  /// system.tracking_*_dir; empty: one flight over all frames.
  std::vector<Sortie> sorties;
  /// The dataset stamp that is simulated time 0 (empty: frame 0's): robots of
  /// a mission share one clock and take off when their first frame is due.
  std::optional<double> clock_origin;
};

/// One agent reset of the run (system.agent_reset).
struct AgentResetRecord {
  double at_s = 0;                      ///< [s] simulated time
  std::size_t frame = 0;                ///< the first dataset frame of the new session
  bool takeoff = false;                 ///< a sortie's take-off after a landing, not a crash
  std::uint32_t old_session = 0, new_session = 0;
  std::size_t spool_carried = 0;        ///< old-session submaps still in the spool, sent on
  std::int64_t bytes_sent_before = 0;   ///< the old pipeline's uplink bytes [B]
  std::int64_t submaps_sent_before = 0; ///< the old pipeline's submaps
  std::int64_t window_bytes_before = 0; ///< the old pipeline's windows as cut (WindowCounters::window_bytes)
};

struct OfflineAgent {
  std::string name;
  std::unique_ptr<Dataset> dataset;
  std::unique_ptr<agent::AgentPipeline> pipeline;
  std::size_t frames = 0, next = 0;  ///< frames to feed, next index
  double clock_offset = 0;           ///< dataset stamp of frame 0 (sim t = stamp - offset)
  std::optional<RobotId> robot;      ///< server robot id once a submap was accepted
  std::size_t acked = 0, lost_messages = 0;
  std::size_t resent = 0;      ///< frames handed to the link again (same session and seq)
  std::size_t duplicates = 0;  ///< frames the server only acknowledged again (already accepted)
  std::set<std::pair<std::uint32_t, std::uint64_t>> sent;  ///< (session, seq) handed to the link
  double next_retry = 0;  ///< [s] after the last frame: next try of a deferred window
  /// Body poses in the world as the robot knew them when it tracked each frame
  /// (its odometry through the server's latest world <- odom; from the first one on).
  Trajectory global_track;
  std::vector<AgentResetRecord> resets;  ///< its restarts / map resets / take-offs so far
  std::vector<Sortie> sorties;           ///< AgentSource::sorties
  std::size_t sortie = 0;                ///< the sortie flying (or the last one landed)
  bool landed = false;                   ///< between two sorties
  std::size_t windows_lost_landed = 0;   ///< deferred windows still held at the next take-off
  /// A submap handed to the transport during a step, put on the link after it.
  struct HeldSend {
    double stamp;  ///< sim time of the frame whose feed sent it
    std::uint32_t session;
    std::uint64_t seq;
    std::vector<std::uint8_t> frame;
  };
  std::vector<HeldSend> held;  ///< this step's sends, in the agent's order
  double feeding_stamp = 0;    ///< sim time of the frame being fed
  FrameSkips skips;            ///< frames that could not be read (skipped, every session)
};

/// One server restart of the run (metrics.json "server_restarts").
struct ServerRestart {
  double down_at_s = 0, up_at_s = 0;  ///< [s] simulated destruction and re-creation
  double resume_ms = 0;               ///< wall time of re-creating it from disk [ms]
  std::string checkpoint;             ///< file it resumed from (empty: journal only)
  std::vector<std::string> problems;  ///< files refused on resume, with reasons
  std::size_t journal_replayed = 0;   ///< accepted after that checkpoint, queued again
  std::size_t frames_lost_down = 0;   ///< frames that arrived while there was no server
  std::size_t resends_before = 0;     ///< agents' resends up to the destruction
  double first_accept_s = -1;         ///< [s] simulated time of the first new submap accepted after it
};

/// The server's health at one moment (system.health_period_s; a soak's plots).
struct HealthSample {
  double time_s = 0;               ///< [s] simulated
  double wall_s = 0;               ///< [s] since the run started
  std::size_t state_bytes = 0;     ///< Server::saveState() size (what a checkpoint writes) [B]
  std::size_t rss_bytes = 0;       ///< resident memory of the process (server and agents) [B]
  std::size_t keyframes = 0, landmarks = 0;  ///< in the global map
  std::size_t pending = 0;         ///< submaps queued at the server
  std::size_t merged = 0;          ///< submaps merged so far
  std::size_t submaps = 0;         ///< submaps the server processed since the last sample
  double submap_ms_median = 0, submap_ms_p95 = 0;  ///< their server time [ms]
  int agents_merged = 0;
  int flying = 0;                  ///< agents between take-off and landing
  bool server_up = true;
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
  /// Thread- and signal-safe: at its next step run() stops feeding frames, flushes
  /// each agent's window and finishes without waiting for the links (the server
  /// merges what arrived).
  void requestStop() { stop_requested_.store(true); }
  /// True when run() ended before the end of the data (requestStop()).
  bool stoppedEarly() const { return stopped_early_; }

  const std::vector<OfflineAgent>& agents() const { return agents_; }
  const server::Server& server() const { return *server_; }
  bool hasServer() const { return server_ != nullptr; }  ///< false while it is down
  /// For test/bench hooks (MapManager::setCandidateHook) before run(); use
  /// onServerCreated() for hooks that must survive a restart.
  server::Server& server() { return *server_; }
  /// Applies `setup` to the server now and to every server created again after a restart.
  void onServerCreated(std::function<void(server::Server&)> setup);
  const std::vector<ServerRestart>& restarts() const { return restarts_; }
  /// The shared link (runs without a scenario; unused with one).
  const SharedLink& link() const { return *link_; }
  /// The server's downlink to the robots (null with server.downlink.enabled false or a scenario).
  const DownlinkChannel* downlink() const { return downlink_.get(); }
  /// The scenario's network (null without link.scenario).
  const RelayNetwork* network() const { return network_.get(); }
  const std::vector<BandwidthSample>& bandwidth() const { return bandwidth_; }
  const std::vector<HealthSample>& health() const { return health_; }
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
  /// Feeds every agent's due frames (side by side, system.agent_threads), then
  /// transmits what they sent in single-thread order.
  Status feedDueFrames(double t);
  /// Agent i's frames due by t, in order (runs on a worker thread).
  Status feedAgent(std::size_t i, double t);
  /// Puts agent i's submap on the link (or the scenario's network) now.
  void transmit(std::size_t i, std::uint32_t session, std::uint64_t seq,
                const std::vector<std::uint8_t>& frame);
  void deliver(double t);
  /// A submap of agent `i` reached the server at `arrival`: whether it is acknowledged.
  bool receive(std::size_t i, std::uint32_t session, std::uint64_t seq,
               const std::vector<std::uint8_t>& bytes, double arrival);
  void acknowledge(double t);
  /// Builds the scenario's network (link.scenario) and its hooks.
  Status createNetwork(const std::string& spool_root);
  void sample(double t);
  /// Destroys / re-creates the server at the configured restart times.
  Status restartServer(double t);
  /// Agent i's pipeline over its spool (emptied first when `fresh`), uplink attached.
  Expected<std::unique_ptr<agent::AgentPipeline>> makePipeline(std::size_t i, bool fresh);
  /// Sorts system.agent_reset and checks each names an agent, before its last frame.
  Status checkResets();
  /// Recreates the pipelines of the agents due to reset at t (system.agent_reset).
  Status resetAgents(double t);
  /// Agent i's pipeline destroyed and made again over its spool (next session),
  /// as a crash (reset) or after a landing (take-off: the sortie's replay set up).
  Status replacePipeline(std::size_t i, double t, bool takeoff);
  /// The frame after agent a's current sortie (its landing), a.frames for the last.
  static std::size_t sortieEnd(const OfflineAgent& a);
  /// Sets up sortie s's tracking replay on agent i's pipeline (none: live).
  Status setUpSortie(std::size_t i, std::size_t s);
  void sampleHealth(double t);
  /// Agents past their last frame try their deferred window again (one per period).
  void retryCarriedWindows(double t);

  struct PendingAck {
    double time;
    std::size_t agent;
    std::uint32_t session;
    std::uint64_t seq;
  };
  /// A world <- odom update on its way to a robot (after a merge).
  struct PendingGlobal {
    double time;
    std::size_t agent;
    GlobalPoseUpdate update;
  };
  /// After a merge: every anchored robot's world <- odom goes down the link.
  void sendGlobalPoses(double t);
  /// Every server period: the downlink's packets for the placed robots (downlink_channel.h).
  void sendDownlink(double t);
  /// Downlink packets and acknowledgements due by t.
  void receiveDownlink(double t);
  struct MessageKey {
    std::size_t agent;
    std::uint32_t session;
    std::uint64_t seq;
  };

  SystemParams params_;
  std::unique_ptr<SharedLink> link_;
  std::unique_ptr<RelayNetwork> network_;
  std::unique_ptr<DownlinkChannel> downlink_;  ///< server.downlink (runs without a scenario)
  std::vector<double> last_own_bytes_;  ///< scenario runs: per agent, at the last sample
  std::unique_ptr<server::Server> server_;
  std::vector<OfflineAgent> agents_;
  std::map<std::uint64_t, MessageKey> messages_;  ///< link message id -> submap
  std::uint64_t next_message_ = 0;
  std::vector<PendingAck> acks_;                  ///< sorted by time on use
  std::vector<PendingGlobal> globals_;            ///< in time order
  std::vector<BandwidthSample> bandwidth_;
  std::vector<HealthSample> health_;
  double next_health_ = 0;
  std::size_t health_submaps_ = 0;  ///< the server's submap timings at the last sample
  std::chrono::steady_clock::time_point wall_start_;
  std::atomic<bool> stop_requested_{false};
  bool stopped_early_ = false;
  std::map<std::string, std::vector<std::pair<double, double>>> estimates_;
  std::vector<std::size_t> last_transmitted_;
  std::string base_dir_;
  std::function<void(server::Server&)> server_setup_;
  std::vector<ServerRestart> restarts_;
  std::size_t next_restart_ = 0;
  std::vector<AgentReset> resets_;  ///< system.agent_reset by time
  std::size_t next_reset_ = 0;
  std::string spool_root_;
  double server_up_at_ = -1;  ///< [s] while the server is down: when it comes back
  double now_ = 0, next_sample_ = 0, next_server_ = 0;
  bool holding_ = false;  ///< inside feedDueFrames: sends are held per agent
};

}  // namespace hermes::system
