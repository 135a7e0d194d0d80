// The agent's window cut (DESIGN.md §3): every window.period_s the keyframes the
// tracker inserted since the previous window, with their landmarks and odometry,
// become one Submap for distillation (submap_window.h buildWindow). Windows are
// consecutive: each starts with the keyframe after the previous window's last,
// and ends at the newest keyframe local mapping has finished with
// (Tracker::mappedKeyframes: in parallel mapping the newest whose BA was
// applied, a consistent point). The first window is due period_s after the
// map's first keyframe. Each window carries the tracking health of the frames
// since the previous one (the distiller spends more on windows in trouble).
//
// It is the window source of the window step (window_step.h: takeWindowIfDue,
// motionHint), standing between the tracker and distillation in the agent
// pipeline (agent_pipeline.cc).
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>

#include "hermes/agent/submap_window.h"
#include "hermes/agent/tracker.h"
#include "hermes/core/map_types.h"
#include "hermes/distill/scores.h"

namespace hermes {

class WindowCut {
 public:
  /// Cuts the map of `tracker` (which must outlive it) every params.period_s.
  WindowCut(Tracker& tracker, const SubmapWindowParams& params);

  /// Identity written into the headers of the windows.
  void setAgent(const Uuid& agent, std::uint32_t session);
  /// The keyframes inserted since the previous window once `t` is at least
  /// period_s after the previous window's hand-over; nullopt otherwise or if no
  /// new keyframe is mapped yet.
  std::optional<Submap> takeWindowIfDue(double t);
  /// The tracker's latest motion with the tracking health of the last window
  /// handed out (the distiller's hint).
  distill::MotionHint motionHint() const;
  /// The tracker started a new map (Tracker::startNewMap): windows start again
  /// from its first keyframe and are numbered anew (a new session).
  void restart();

 private:
  Tracker& tracker_;
  SubmapWindowParams params_;
  SubmapHeader header_;
  std::size_t next_kf_ = 0;   ///< first keyframe of the next window
  double last_t_ = 0;         ///< [s] the previous hand-over
  bool started_ = false;
  distill::TrackingHealth health_;  ///< of the last window handed out
};

}  // namespace hermes
