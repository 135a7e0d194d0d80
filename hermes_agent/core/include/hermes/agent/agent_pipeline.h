// One agent, ROS-free, one door in: feed(frame). Tracks with the front end
// (Tracker), keeps the body trajectory in the dataset's ground-truth frame
// convention (T_W_B = T_W_C * T_B_C^-1; W is the odometry frame = first camera
// pose), counts lost frames and times each stage. The 5-s window -> distill ->
// encode step (window_step.h) runs whenever the tracker hands out a window
// (Tracker::takeWindowIfDue). With an uplink attached (attachUplink) the encoded
// submaps go to an UplinkSender (disk spool, exactly-once delivery through the
// caller's transport) and the coordinator plans with its measured bandwidth and
// backlog; without one they are only counted (single-agent runs).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <utility>
#include <string>

#include "hermes/agent/bandwidth_monitor.h"
#include "hermes/agent/odometry_corruption.h"
#include "hermes/agent/run_config.h"
#include "hermes/agent/tracker.h"
#include "hermes/agent/uplink_sender.h"
#include "hermes/agent/window_step.h"
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

  /// Tracks one frame (stereo: left+right, RGB-D: left+depth). Errors: malformed
  /// frame, or a stamp not after the previous one.
  Expected<TrackResult> feed(const CameraFrame& frame);

  const std::string& name() const { return name_; }
  /// Body poses of every successfully tracked frame, in time order.
  const Trajectory& trajectory() const { return trajectory_; }
  std::int64_t frames() const { return frames_; }
  std::int64_t lostFrames() const { return lost_; }
  /// Fraction of fed frames not tracked (lost, or not yet initialised).
  double lostRate() const { return frames_ > 0 ? double(lost_) / double(frames_) : 0.0; }
  const TimingStats& timings() const { return timings_; }
  const Tracker& tracker() const { return tracker_; }
  /// Windows distilled and encoded so far (all zero until windows exist).
  const WindowCounters& windows() const { return windows_; }
  std::int64_t submapsSent() const { return windows_.sent; }
  std::int64_t bytesSent() const { return windows_.bytes; }

  /// This agent's share of the metrics JSON (no accuracy fields: see fillAccuracy).
  AgentMetrics metrics() const;

  /// Connects the window step to an uplink: opens the spool (params.uplink.buffer.dir),
  /// starts a new session, and from then on every encoded window is submitted to an
  /// UplinkSender that hands frames to `transport`. Uplink time = frame stamp -
  /// `clock_offset_s` (the offline runner's simulated clock starts at 0 for every
  /// agent). Call once, before the first frame. Errors: spool cannot be opened.
  Status attachUplink(UplinkSender::Transport transport, double clock_offset_s = 0);
  /// Replaces the stamp-based uplink clock by `clock` (e.g. wall time in a ROS
  /// node, where frame stamps and the network need not advance together).
  void setUplinkClock(std::function<double()> clock) { uplink_clock_ = std::move(clock); }
  /// Server acknowledgement at uplink time `now` (duplicates are fine).
  Status onAck(std::uint32_t session, std::uint64_t seq, double now);
  /// Lets the uplink send what it may at uplink time `now` (feed() also does).
  void pollUplink(double now);
  /// End of the sequence: distils and submits the open (partial) window now.
  void flushWindow();
  /// After the end of the sequence: a window deferred or refused (link too slow,
  /// spool full) is distilled again at uplink time `now` and submitted if it fits.
  /// Call once per window period while draining.
  void retryCarriedWindow(double now);
  /// A deferred / refused window waits to be sent.
  bool hasCarriedWindow() const { return windows_.carry.has_value(); }
  /// Test hook: from now on the odometry (trajectory and windows) is corrupted
  /// as `params` says (odometry_corruption.h). Call before the first frame.
  void setOdometryCorruption(const OdometryCorruptionParams& params);
  /// Loops the server reports for this agent (the coordinator's alpha rule).
  void setLoopClosures(int loops) { loop_closures_ = loops; }
  /// Null until attachUplink().
  const UplinkSender* uplink() const { return uplink_.get(); }
  UplinkSender* uplink() { return uplink_.get(); }
  const Uuid& agentId() const { return agent_id_; }
  /// (session, seq) of the last submap handed to the uplink, nullopt before the first.
  std::optional<std::pair<std::uint32_t, std::uint64_t>> lastSubmitted() const {
    return last_window_;
  }
  std::uint32_t session() const { return session_; }

 private:
  AgentPipeline(const AgentPipelineParams& params, const std::string& name,
                const AgentCamera& camera, std::unique_ptr<distill::Distiller> distiller);
  /// The window step at tracker time `stamp` (uplink time: the last frame's;
  /// when retrying the carried window: stamp - clock offset).
  void windowStep(double stamp, bool retry_carry = false);

  AgentPipelineParams params_;
  std::string name_;
  AgentCamera camera_;
  SE3 T_C_B_;
  Tracker tracker_;
  std::unique_ptr<distill::Distiller> distiller_;
  Trajectory trajectory_;
  Uuid agent_id_{};
  std::uint32_t session_ = 1;
  std::unique_ptr<UplinkSender> uplink_;
  double clock_offset_ = 0;
  std::function<double()> uplink_clock_;
  int loop_closures_ = 0;
  std::optional<std::pair<std::uint32_t, std::uint64_t>> last_window_;  ///< last submitted
  bool last_window_acked_ = false;
  std::int64_t frames_ = 0, lost_ = 0;
  BandwidthMonitor monitor_;
  std::unique_ptr<OdometryCorruptor> corruptor_;
  WindowCounters windows_;
  double last_stamp_ = 0;
  TimingStats timings_;
};

}  // namespace hermes::agent
