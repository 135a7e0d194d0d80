// One agent, ROS-free, one door in: feed(frame). Its stages, in the order
// feed() runs them:
//   tracking (Tracker: features, pose, keyframe policy)
//   -> local mapping of each new keyframe (MappingStage, inside the tracker: the
//      motion model follows what the BA moves)
//   -> window cut every window period (WindowCut: the map since the last window)
//   -> distillation and encoding (window_step.h, distill::Distiller)
//   -> uplink (UplinkSender: disk spool, exactly-once delivery through the
//      caller's transport; the coordinator plans with its measured bandwidth and
//      backlog; without an uplink the submaps are only counted).
// It keeps the body trajectory in the dataset's ground-truth frame convention
// (T_W_B = T_W_C * T_B_C^-1; W is the odometry frame = first camera pose),
// counts lost frames, starts a new map after a long loss, and times each stage.
//
// Threads (agent_threads.h, DESIGN §9). Synchronous mode (params.threads.parallel
// false, config `agent.parallel: false`, the default): every stage runs inside
// feed(), deterministic and bit-identical to the single-threaded pipeline (the
// offline runner and the tests rely on it). Parallel mode (`agent.parallel:
// true` or setParallel(true) before the first frame; the nodelet's choice):
// feed() tracks and returns without waiting for local BA (mapper thread,
// mapping_stage.h) or the window step (uplink thread: distill, encode, spool, send;
// bounded queue, windows merged when it is full, never dropped). Then:
//  * feed(), onAck(), pollUplink(), flushWindow(), retryCarriedWindow() and the
//    accessors are called from one thread at a time (the caller's; the nodelet
//    serialises its callbacks), as before;
//  * the uplink transport is also called from the uplink thread, always under
//    the pipeline's uplink lock (never two calls at once);
//  * feed() does not poll the uplink (pollUplink / onAck and the uplink thread
//    do); flushWindow() waits for both workers and drains their queues; the
//    destructor finishes queued windows and joins the threads;
//  * uplink() is for single-threaded use; read the sender through withUplink().
//
// The experiment and test hooks wrap the tracking stage (tracking_front.h), so
// feed() reads the same with or without them: odometry corruption
// (setOdometryCorruption), tracking record (recordTracking: every feed() and
// flushWindow() also appends what the tracker produced, the window cut and the
// motion hint to a recording) and replay (replayTracking: no image is tracked;
// replayFrame(stamp) takes the next recorded frame instead of feed() and the
// window step runs on the recorded windows, exactly as it ran on the
// tracker's). Record and replay need synchronous mode.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <utility>
#include <vector>
#include <string>

#include "hermes/agent/agent_threads.h"
#include "hermes/agent/bandwidth_monitor.h"
#include "hermes/agent/borrowed_map.h"
#include "hermes/agent/run_config.h"
#include "hermes/agent/tracker.h"
#include "hermes/agent/tracking_front.h"
#include "hermes/agent/uplink_sender.h"
#include "hermes/agent/window_cut.h"
#include "hermes/agent/window_step.h"
#include "hermes/core/global_pose.h"
#include "hermes/core/map_down.h"
#include "hermes/core/metrics.h"
#include "hermes/core/trajectory.h"
#include "hermes/distill/distiller.h"

namespace hermes::agent {

/// Camera set-up of the agent: the images handed to feed() live in K.
struct AgentCamera {
  PinholeIntrinsics K;
  double baseline = 0;  ///< [m] rectified stereo baseline; 0 for RGB-D
  SE3 T_B_C;            ///< body <- tracked camera
};

class AgentPipeline {
 public:
  /// Fails when the params are invalid or the camera is unusable.
  static Expected<std::unique_ptr<AgentPipeline>> create(const AgentPipelineParams& params,
                                                         const std::string& name,
                                                         const AgentCamera& camera);
  ~AgentPipeline();
  AgentPipeline(const AgentPipeline&) = delete;
  AgentPipeline& operator=(const AgentPipeline&) = delete;

  /// Switches to parallel (worker threads) or synchronous mode; overrides
  /// params.threads.parallel. Call before the first frame (error otherwise).
  Status setParallel(bool parallel);
  bool parallel() const { return window_worker_ != nullptr; }
  /// Test hook: runs on the mapper thread before every local BA solve (e.g. to
  /// hold the mapper back). Parallel mode, before the first frame.
  Status setMapperHook(std::function<void()> before_solve);
  /// Counters of the stages and their queues (both modes).
  AgentThreadStats threadStats() const;

  /// Tracks one frame (stereo: left+right, RGB-D: left+depth). Errors: malformed
  /// frame, or a stamp not after the previous one.
  Expected<TrackResult> feed(const CameraFrame& frame);

  /// Records the tracking from the first frame on into `writer` (synchronous
  /// mode, before the first frame). flushWindow() records the last step;
  /// finishTracking() then writes the summary.
  Status recordTracking(std::unique_ptr<TrackingLogWriter> writer);
  /// After flushWindow(): closes the recording, or checks that the whole
  /// recording was replayed; the first error of either (ok otherwise).
  Status finishTracking();
  /// Replay mode (synchronous, before the first frame): feed() is refused and
  /// replayFrame() takes the recorded frames in order.
  Status replayTracking(TrackingLog log);
  bool replaying() const { return replay_ != nullptr; }
  /// Replay mode: the recorded frame at `stamp` (the next one) as feed() would
  /// have tracked it. Errors: not replaying, the recording ends or is out of step.
  Expected<TrackingStatus> replayFrame(double stamp);

  const std::string& name() const { return name_; }
  /// Body poses of every successfully tracked frame, in time order.
  const Trajectory& trajectory() const { return trajectory_; }
  std::int64_t frames() const { return frames_; }
  /// New maps started after a loss (tracker.reinit_after_s), each a new session.
  std::int64_t newMaps() const { return new_maps_; }
  std::int64_t lostFrames() const { return lost_; }
  /// Fraction of fed frames not tracked (lost, or not yet initialised).
  double lostRate() const { return frames_ > 0 ? double(lost_) / double(frames_) : 0.0; }
  /// Per-stage timings: track, window (the cut alone in parallel mode),
  /// agent_total (feed() as a whole), distill, encode (on the uplink thread in
  /// parallel mode).
  TimingStats timings() const;
  /// The live tracker (empty while replaying: see metrics()).
  const Tracker& tracker() const { return tracker_; }
  /// Windows distilled and encoded so far (all zero until windows exist). In
  /// parallel mode a copy of the counters as of the uplink stage's last job,
  /// without the carried / held maps (hasCarriedWindow tells).
  WindowCounters windows() const;
  std::int64_t submapsSent() const { return windows().sent; }
  std::int64_t bytesSent() const { return windows().bytes; }

  /// This agent's share of the metrics JSON (no accuracy fields: see fillAccuracy).
  AgentMetrics metrics() const;

  /// Connects the window step to an uplink: opens the spool (params.uplink.buffer.dir),
  /// starts a new session, and from then on every encoded window is submitted to an
  /// UplinkSender that hands frames to `transport`. Uplink time = frame stamp -
  /// `clock_offset_s` (the offline runner's simulated clock starts at 0 for every
  /// agent). Call once, before the first frame. Errors: spool cannot be opened.
  /// `transport` runs under the pipeline's uplink lock (on the uplink thread in
  /// parallel mode): it must not call back into the pipeline.
  Status attachUplink(UplinkSender::Transport transport, double clock_offset_s = 0);
  /// Replaces the stamp-based uplink clock by `clock` (e.g. wall time in a ROS
  /// node, where frame stamps and the network need not advance together).
  void setUplinkClock(std::function<double()> clock) {
    std::lock_guard<std::mutex> lock(uplink_mu_);
    uplink_clock_ = std::move(clock);
  }
  /// Server acknowledgement at uplink time `now` (duplicates are fine).
  Status onAck(std::uint32_t session, std::uint64_t seq, double now);
  /// A relay robot holds the submap durably (UplinkSender::onHandedOver): counts
  /// as delivered for the monitor and the probing rule; the spool keeps it until
  /// the server's acknowledgement comes back through the relay (onAck).
  Status onHandedOver(std::uint32_t session, std::uint64_t seq, double now);
  /// Lets the uplink send what it may at uplink time `now` (feed() also does).
  void pollUplink(double now);
  /// The transport lost what was in flight (e.g. an MQTT broker that forgot our
  /// session): everything unacknowledged is sent again (UplinkSender::onReconnect).
  void onUplinkReconnect();
  /// End of the sequence: distils and submits the open (partial) window now.
  /// Parallel mode: first finishes the local BAs, and returns once the uplink
  /// stage has distilled and submitted everything queued.
  void flushWindow();
  /// After the end of the sequence: a window deferred or refused (link too slow,
  /// spool full) is distilled again at uplink time `now` and submitted if it fits.
  /// Call once per window period while draining. Parallel mode: queued for the
  /// uplink thread.
  void retryCarriedWindow(double now);
  /// A deferred / refused window waits to be sent.
  bool hasCarriedWindow() const;
  /// Test hook: from now on the odometry (trajectory and windows) is corrupted
  /// as `params` says (odometry_corruption.h). Call before the first frame.
  void setOdometryCorruption(const OdometryCorruptionParams& params);
  /// Loops the server reports for this agent (the coordinator's alpha rule).
  void setLoopClosures(int loops) { loop_closures_.store(loops); }
  /// Null until attachUplink(). Not for parallel mode while frames flow (the
  /// uplink thread uses the sender): see withUplink().
  const UplinkSender* uplink() const { return uplink_.get(); }
  UplinkSender* uplink() { return uplink_.get(); }
  /// Calls `f(const UplinkSender*)` (null without an uplink) under the uplink
  /// lock and returns its result: safe in both modes.
  template <typename F>
  auto withUplink(F&& f) const {
    std::lock_guard<std::mutex> lock(uplink_mu_);
    return f(static_cast<const UplinkSender*>(uplink_.get()));
  }
  const Uuid& agentId() const { return agent_id_; }
  /// (session, seq) of the last submap handed to the uplink, nullopt before the first.
  std::optional<std::pair<std::uint32_t, std::uint64_t>> lastSubmitted() const {
    std::lock_guard<std::mutex> lock(uplink_mu_);
    return last_window_;
  }
  /// Every (session, seq) handed to the uplink, in order, from index `from` on
  /// (a caller that keeps count sees each once, however many windows one step sent).
  std::vector<std::pair<std::uint32_t, std::uint64_t>> submittedFrom(std::size_t from) const {
    std::lock_guard<std::mutex> lock(uplink_mu_);
    if (from >= submitted_.size()) return {};
    return {submitted_.begin() + static_cast<std::ptrdiff_t>(from), submitted_.end()};
  }
  std::uint32_t session() const { return session_; }

  /// The server's world <- odometry for this robot after a merge (global_pose.h);
  /// false when not taken (another session, older than the one held, not finite).
  /// Any thread.
  bool onGlobalPose(const GlobalPoseUpdate& update, double now);
  /// What this robot knows of its place in the global map (empty before the first).
  GlobalPoseState globalPose() const {
    std::lock_guard<std::mutex> lock(global_mu_);
    return global_pose_;
  }

  /// A downlink packet (core/map_down.h) at `now`: kept in the borrowed map
  /// (borrowed_map.h); the acknowledgement to send back when the robot holds
  /// it (taken now or before), an error naming why it was refused (malformed,
  /// for another robot). Any thread. While the current session is not placed
  /// in the world, each new keyframe is relocalised against the borrowed map
  /// (live tracking only): a success places the session at once (globalPose()).
  /// Nothing borrowed enters the robot's own map or its submaps.
  Expected<MapDownAck> onMapDown(const std::uint8_t* data, std::size_t size, double now);
  struct BorrowedStats {
    std::uint64_t packets = 0, duplicates = 0, refused = 0;
    std::size_t keyframes = 0, landmarks = 0, memory_bytes = 0;
    std::int64_t attempts = 0;          ///< keyframes relocalised against it
    std::int64_t relocalisations = 0;   ///< of those, placed the session in the world
  };
  BorrowedStats borrowedStats() const;
  /// When each session began and was first placed in the world (uplink time).
  struct SessionPlacement {
    std::uint32_t session = 0;
    double started = 0;        ///< [s] its first frame
    double placed = -1;        ///< [s] first placed (-1: not yet)
    bool by_borrowed = false;  ///< by the borrowed map (else by the server's world <- odom)
  };
  std::vector<SessionPlacement> placements() const {
    std::lock_guard<std::mutex> lock(global_mu_);
    return placements_;
  }

 private:
  AgentPipeline(const AgentPipelineParams& params, const std::string& name,
                const AgentCamera& camera, std::unique_ptr<distill::Distiller> distiller);
  /// The window step at tracker time `stamp` (uplink time: the last frame's;
  /// when retrying the carried window: stamp - clock offset).
  void windowStep(double stamp, bool retry_carry = false);
  /// A frame stamp must be finite and after the previous frame's (feed, replayFrame).
  Status checkStamp(double stamp) const;
  /// One frame (null: replayed) through the front, the lost-and-new-map rule
  /// and the window step.
  Expected<FrontStep> trackStep(const CameraFrame* frame, double stamp);
  /// Points front_ at the outermost front: (recording)(corrupted)(live), or the replay.
  void stackFronts();
  /// Hands an encoded window to the uplink at uplink time `now` (parallel mode:
  /// under uplink_mu_) and tells the monitor whether the previous one arrived.
  Status submitWindow(const Submap& submap, std::vector<std::uint8_t>&& bytes, double now);
  /// The sink of a window step at uplink time `now`: what the server reported
  /// (loops, placed) and submitWindow, under `lock` when given (threaded mode).
  WindowSink makeSink(double now, double backlog_bytes, std::mutex* lock);

  /// Parallel mode: one job of the uplink stage.
  struct WindowJob {
    std::optional<Submap> window;  ///< nullopt: retry the carried window
    distill::MotionHint motion;    ///< tracker motion at the cut
    double stamp = 0;              ///< [s] tracker time of the step
    double link_stamp = 0;         ///< [s] stamp the uplink clock derives from
    int periods = 1;               ///< window periods it stands for (merged jobs: more)
    bool drop_carry = false;       ///< a new map began: the old session's carry cannot join
  };
  void startWorkers(bool parallel);
  /// Cuts the due window (or a due retry) and queues it (caller's thread).
  void queueWindowStep(double stamp, double link_stamp);
  /// Runs on the uplink thread.
  void runWindowJob(WindowJob& job);
  /// The uplink stage's counters as the caller's accessors see them.
  void publishWindowCounters(const TimingStats& job_timings);

  AgentPipelineParams params_;
  std::string name_;
  AgentCamera camera_;
  SE3 T_C_B_;
  Tracker tracker_;    ///< tracking, keyframes, local mapping (mapping_stage.h)
  WindowCut window_;   ///< the map since the last window, every window period
  LiveFront live_;     ///< tracker_ + window_ as the window step's source
  std::unique_ptr<distill::Distiller> distiller_;
  Trajectory trajectory_;
  Uuid agent_id_{};
  std::uint32_t session_ = 1;
  mutable std::mutex global_mu_;
  GlobalPoseState global_pose_;
  std::vector<SessionPlacement> placements_;  ///< under global_mu_
  /// Uplink time of a frame stamp (the uplink clock when one is set).
  double uplinkTime(double stamp) const;
  /// Places the current session by the borrowed map from the newest keyframe
  /// (when not placed yet); tells the borrowed map where the robot is otherwise.
  void placeByBorrowedMap(double stamp);
  mutable std::mutex borrowed_mu_;  ///< borrowed_ and its counters
  BorrowedMap borrowed_;
  std::int64_t borrowed_attempts_ = 0, borrowed_relocalisations_ = 0;
  std::vector<std::pair<std::uint32_t, std::uint64_t>> submitted_;  ///< under uplink_mu_
  std::unique_ptr<UplinkSender> uplink_;
  double clock_offset_ = 0;
  std::function<double()> uplink_clock_;
  std::atomic<int> loop_closures_{0};
  mutable std::mutex uplink_mu_;  ///< uplink_ (sender, its monitor), last_window_*
  std::optional<std::pair<std::uint32_t, std::uint64_t>> last_window_;  ///< last submitted
  bool last_window_acked_ = false;
  std::int64_t frames_ = 0, lost_ = 0;
  std::int64_t new_maps_ = 0;
  double lost_since_ = -1;  ///< stamp of the first frame of the current loss; < 0: tracking
  /// Lost for tracker.reinit_after_s: the open window goes out, then a new map in a
  /// new session starts at the last body pose (tracking never ends for good).
  void startNewMap();
  BandwidthMonitor monitor_;
  std::unique_ptr<CorruptedFront> corrupted_;  ///< the hooks (tracking_front.h)
  std::unique_ptr<RecordingFront> recording_;
  std::unique_ptr<ReplayFront> replay_;
  TrackingFront* front_ = &live_;  ///< the outermost front (stackFronts)
  WindowCounters windows_;
  double last_stamp_ = 0;
  TimingStats timings_;
  // Parallel mode.
  double window_s_ = 5;             ///< distill.window_s (carried-window retries)
  std::int64_t window_retries_ = 0;
  WindowCounters stage_windows_;    ///< the uplink thread's own (with carry / held)
  mutable std::mutex stats_mu_;     ///< the published copies below
  TimingStats stage_timings_;       ///< distill / encode on the uplink thread
  bool carry_pending_ = false;      ///< published: a window is carried
  double carry_stamp_ = 0;
  std::function<void()> mapper_hook_;
  std::unique_ptr<StageWorker<WindowJob>> window_worker_;  ///< last: stopped first
};

}  // namespace hermes::agent
