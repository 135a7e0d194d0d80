// The tracking stage as the agent pipeline sees it (agent_pipeline.h): one step
// per frame gives a tracking result and a body pose in the odometry frame, and
// the window step (window_step.h) cuts its windows from it (takeWindowIfDue,
// motionHint). LiveFront tracks images with the Tracker and cuts with the
// WindowCut. The experiment and test hooks wrap a front instead of branching
// in the pipeline:
//  * CorruptedFront: the odometry jumps or drifts (odometry_corruption.h) in
//    the poses and in every window it hands out; a noticed jump marks the
//    tracker lost, as a relocalisation would;
//  * RecordingFront: appends every step (frame or end-of-sequence flush) of the
//    front it wraps to a recording (tracking_log.h), with the window the step
//    cut and the motion hint after the cut;
//  * ReplayFront: tracks no image; hands out the recorded steps, windows and
//    hints in order, as the recorded front did.
// The pipeline stacks them in one order whatever order they were set in:
// (Recording)(Corrupted)(Live), or Replay alone.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <utility>

#include "hermes/agent/odometry_corruption.h"
#include "hermes/agent/tracker.h"
#include "hermes/agent/tracking_log.h"
#include "hermes/agent/window_cut.h"

namespace hermes::agent {

/// One frame through a front.
struct FrontStep {
  TrackResult result;  ///< what the tracker reported (replayed: the status only)
  SE3 T_W_B;           ///< body pose in the odometry frame (status kOk)
};

class TrackingFront {
 public:
  virtual ~TrackingFront() = default;
  /// Tracks the frame at `stamp`; `frame` is null for a front that needs no
  /// images (needsImages() false). Stamps increase; the same stamp again is
  /// the pipeline's retry after it started a new map.
  virtual Expected<FrontStep> track(const CameraFrame* frame, double stamp) = 0;
  /// The end-of-sequence flush at `stamp`, before its window step.
  virtual Status beginFlush(double stamp) {
    (void)stamp;
    return Status::Ok();
  }
  /// After the window step of a frame (`step`) or of the flush (null).
  virtual Status endStep(const FrontStep* step, double stamp) {
    (void)step;
    (void)stamp;
    return Status::Ok();
  }
  /// The window step's source (window_step.h).
  virtual std::optional<Submap> takeWindowIfDue(double t) = 0;
  virtual distill::MotionHint motionHint() const = 0;
  virtual bool needsImages() const { return true; }
  /// A long loss may start a new map (the pipeline's startNewMap); a recording
  /// or a replay holds one map.
  virtual bool startsNewMaps() const { return false; }
  /// The tracker's totals (metrics); frames and lost are the pipeline's.
  virtual TrackingSummary summary() const = 0;
  /// End of the run (frames, lost: the pipeline's counts): closes a recording,
  /// checks that a replay was taken whole; the first error of the run.
  virtual Status finish(std::int64_t frames, std::int64_t lost) {
    (void)frames;
    (void)lost;
    return Status::Ok();
  }
};

class LiveFront : public TrackingFront {
 public:
  /// `tracker` and `cut` outlive the front; T_C_B: tracked camera <- body.
  LiveFront(Tracker& tracker, WindowCut& cut, const SE3& T_C_B)
      : tracker_(tracker), cut_(cut), T_C_B_(T_C_B) {}
  Expected<FrontStep> track(const CameraFrame* frame, double stamp) override;
  std::optional<Submap> takeWindowIfDue(double t) override { return cut_.takeWindowIfDue(t); }
  distill::MotionHint motionHint() const override { return cut_.motionHint(); }
  bool startsNewMaps() const override { return true; }
  TrackingSummary summary() const override;

 private:
  Tracker& tracker_;
  WindowCut& cut_;
  SE3 T_C_B_;
};

/// A wrapper's default: everything goes to the front it wraps (set by wrap()).
class FrontWrapper : public TrackingFront {
 public:
  void wrap(TrackingFront* inner) { inner_ = inner; }
  Expected<FrontStep> track(const CameraFrame* frame, double stamp) override {
    return inner_->track(frame, stamp);
  }
  Status beginFlush(double stamp) override { return inner_->beginFlush(stamp); }
  Status endStep(const FrontStep* step, double stamp) override { return inner_->endStep(step, stamp); }
  std::optional<Submap> takeWindowIfDue(double t) override { return inner_->takeWindowIfDue(t); }
  distill::MotionHint motionHint() const override { return inner_->motionHint(); }
  bool needsImages() const override { return inner_->needsImages(); }
  bool startsNewMaps() const override { return inner_->startsNewMaps(); }
  TrackingSummary summary() const override { return inner_->summary(); }
  Status finish(std::int64_t frames, std::int64_t lost) override { return inner_->finish(frames, lost); }

 protected:
  TrackingFront* inner_ = nullptr;
};

class CorruptedFront : public FrontWrapper {
 public:
  /// `tracker` is marked lost at a noticed jump.
  CorruptedFront(const OdometryCorruptionParams& params, Tracker& tracker)
      : corruptor_(params), tracker_(tracker) {}
  Expected<FrontStep> track(const CameraFrame* frame, double stamp) override;
  std::optional<Submap> takeWindowIfDue(double t) override;

 private:
  OdometryCorruptor corruptor_;
  Tracker& tracker_;
  std::optional<double> last_stamp_;  ///< a retry of the same frame jumps once
};

class RecordingFront : public FrontWrapper {
 public:
  explicit RecordingFront(std::unique_ptr<TrackingLogWriter> writer) : writer_(std::move(writer)) {}
  std::optional<Submap> takeWindowIfDue(double t) override;
  Status endStep(const FrontStep* step, double stamp) override;
  bool startsNewMaps() const override { return false; }
  /// Writes the summary and closes the recording (unless a step failed).
  Status finish(std::int64_t frames, std::int64_t lost) override;

 private:
  std::unique_ptr<TrackingLogWriter> writer_;
  std::optional<Submap> taken_;  ///< the window the current step cut
  Status status_;                ///< the first error
};

class ReplayFront : public TrackingFront {
 public:
  explicit ReplayFront(TrackingLog log) : log_(std::move(log)) {}

  /// Moves to the next recorded step, which must be a frame at `stamp` (or the
  /// flush when `flush`). Errors: the recording is exhausted or out of step.
  Expected<const TrackingStep*> next(bool flush, double stamp);
  /// The next recorded frame (next(false, stamp)); `frame` is ignored.
  Expected<FrontStep> track(const CameraFrame* frame, double stamp) override;
  /// The recorded flush (next(true, ..)); its error is kept for finish().
  Status beginFlush(double stamp) override;
  /// The current step's window, once; headers carry the identity given by setAgent.
  std::optional<Submap> takeWindowIfDue(double t) override;
  /// The recorded hint after the current step's cut.
  distill::MotionHint motionHint() const override;
  bool needsImages() const override { return false; }
  TrackingSummary summary() const override { return log_.summary; }
  /// The first error, or steps of the recording left over.
  Status finish(std::int64_t frames, std::int64_t lost) override;
  void setAgent(const Uuid& agent, std::uint32_t session) {
    agent_ = agent;
    session_ = session;
    have_identity_ = true;
  }
  /// Every recorded step was taken.
  bool done() const { return next_ == log_.steps.size(); }

 private:
  TrackingLog log_;
  std::size_t next_ = 0;  ///< steps [0, next_) are done; current = next_ - 1
  Uuid agent_{};
  std::uint32_t session_ = 0;
  bool have_identity_ = false;
  Status status_;  ///< the first flush error
};

}  // namespace hermes::agent
