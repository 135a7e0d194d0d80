// The two stand-ins for the live window cut in the window step (window_step.h
// needs only takeWindowIfDue(stamp) and motionHint()) when tracking is recorded
// or replayed (tracking_log.h):
//  * WindowTap wraps the live window cut and keeps a copy of the window it
//    hands out, for the recording;
//  * ReplayTracker hands out the recorded windows and motion hints, one
//    recorded step (frame or end-of-sequence flush) at a time.
#pragma once

#include <cstddef>
#include <optional>
#include <utility>

#include "hermes/agent/tracking_log.h"
#include "hermes/agent/window_cut.h"

namespace hermes::agent {

class WindowTap {
 public:
  explicit WindowTap(WindowCut& cut) : cut_(cut) {}
  std::optional<Submap> takeWindowIfDue(double t) {
    std::optional<Submap> window = cut_.takeWindowIfDue(t);
    if (window) taken_ = *window;
    return window;
  }
  distill::MotionHint motionHint() const { return cut_.motionHint(); }
  /// The window handed out since construction (nullopt if none).
  std::optional<Submap>& taken() { return taken_; }

 private:
  WindowCut& cut_;
  std::optional<Submap> taken_;
};

class ReplayTracker {
 public:
  explicit ReplayTracker(TrackingLog log) : log_(std::move(log)) {}

  /// Moves to the next recorded step, which must be a frame at `stamp` (or the
  /// flush when `flush`). Errors: the recording is exhausted or out of step.
  Expected<const TrackingStep*> next(bool flush, double stamp);
  /// The current step's window, once (window_step.h); headers carry the
  /// identity given by setAgent.
  std::optional<Submap> takeWindowIfDue(double t);
  /// The tracker's hint after the current step's cut.
  distill::MotionHint motionHint() const;
  void setAgent(const Uuid& agent, std::uint32_t session) {
    agent_ = agent;
    session_ = session;
    have_identity_ = true;
  }
  const TrackingSummary& summary() const { return log_.summary; }
  /// Every recorded step was taken.
  bool done() const { return next_ == log_.steps.size(); }

 private:
  TrackingLog log_;
  std::size_t next_ = 0;  ///< steps [0, next_) are done; current = next_ - 1
  Uuid agent_{};
  std::uint32_t session_ = 0;
  bool have_identity_ = false;
};

}  // namespace hermes::agent
