// One agent, ROS-free, one door in: feed(frame). Tracks with the front end
// (Tracker), keeps the body trajectory in the dataset's ground-truth frame
// convention (T_W_B = T_W_C * T_B_C^-1; W is the odometry frame = first camera
// pose), counts lost frames and times each stage. The 5-s window -> distill ->
// encode step (window_step.h) runs as soon as the tracker hands out windows
// (Tracker::takeWindowIfDue); until then it is a no-op. Handing the encoded
// submaps to an UplinkSender is the server run's part (not here yet).
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "hermes/agent/bandwidth_monitor.h"
#include "hermes/agent/run_config.h"
#include "hermes/agent/tracker.h"
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

 private:
  AgentPipeline(const AgentPipelineParams& params, const std::string& name,
                const AgentCamera& camera, std::unique_ptr<distill::Distiller> distiller);

  AgentPipelineParams params_;
  std::string name_;
  AgentCamera camera_;
  SE3 T_C_B_;
  Tracker tracker_;
  std::unique_ptr<distill::Distiller> distiller_;
  Trajectory trajectory_;
  std::int64_t frames_ = 0, lost_ = 0;
  BandwidthMonitor monitor_;
  WindowCounters windows_;
  double last_stamp_ = 0;
  TimingStats timings_;
};

}  // namespace hermes::agent
