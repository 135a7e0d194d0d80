#include "hermes/agent/tracking_front.h"

#include <string>

namespace hermes::agent {

Expected<FrontStep> LiveFront::track(const CameraFrame* frame, double stamp) {
  if (!frame) return Error{"live tracking at " + std::to_string(stamp) + " s: no frame"};
  auto result = tracker_.feed(*frame);
  if (!result.ok()) return Error{result.error()};
  FrontStep step;
  step.result = std::move(*result);
  // Body pose in the odometry world: T_W_B = T_W_C * T_C_B.
  if (step.result.status == TrackingStatus::kOk) step.T_W_B = step.result.T_W_C * T_C_B_;
  return step;
}

TrackingSummary LiveFront::summary() const {
  TrackingSummary s;
  s.keyframes = static_cast<std::int64_t>(tracker_.keyframes().size());
  s.landmarks = static_cast<std::int64_t>(tracker_.landmarks().size());
  s.total_health = tracker_.totalHealth();
  return s;
}

Expected<FrontStep> CorruptedFront::track(const CameraFrame* frame, double stamp) {
  const bool retry = last_stamp_ && *last_stamp_ == stamp;
  last_stamp_ = stamp;
  if (!retry && corruptor_.noticedJumpAt(stamp)) tracker_.markLost();
  auto step = inner_->track(frame, stamp);
  if (step.ok() && step->result.status == TrackingStatus::kOk)
    step->T_W_B = corruptor_.onFrame(stamp, step->T_W_B) * step->T_W_B;
  return step;
}

std::optional<Submap> CorruptedFront::takeWindowIfDue(double t) {
  std::optional<Submap> window = inner_->takeWindowIfDue(t);
  if (window) corruptor_.apply(&*window);
  return window;
}

std::optional<Submap> RecordingFront::takeWindowIfDue(double t) {
  std::optional<Submap> window = inner_->takeWindowIfDue(t);
  if (window) taken_ = *window;
  return window;
}

Status RecordingFront::endStep(const FrontStep* step, double stamp) {
  if (Status s = inner_->endStep(step, stamp); !s) return s;
  TrackingStep record;
  record.flush = step == nullptr;
  record.stamp = stamp;
  if (step) {
    record.status = step->result.status;
    if (record.status == TrackingStatus::kOk) record.T_W_B = step->T_W_B;
  }
  record.motion = inner_->motionHint();
  record.window = std::move(taken_);
  taken_.reset();
  if (status_) status_ = writer_->append(record);
  return status_;
}

Status RecordingFront::finish(std::int64_t frames, std::int64_t lost) {
  if (Status s = inner_->finish(frames, lost); !s) return s;
  if (!writer_) return status_;
  if (status_) {
    TrackingSummary summary = inner_->summary();
    summary.frames = frames;
    summary.lost = lost;
    status_ = writer_->close(summary);
  }
  writer_.reset();
  return status_;
}

Expected<const TrackingStep*> ReplayFront::next(bool flush, double stamp) {
  const std::string want = flush ? "the end-of-sequence flush" : "a frame at " + std::to_string(stamp) + " s";
  if (next_ >= log_.steps.size())
    return Error{"tracking replay: the recording ends before " + want};
  const TrackingStep& step = log_.steps[next_];
  if (step.flush != flush || (!flush && step.stamp != stamp))
    return Error{"tracking replay out of step: recorded " +
                 (step.flush ? std::string("the flush") : "a frame at " + std::to_string(step.stamp) + " s") +
                 " (step " + std::to_string(next_) + "), this run wants " + want};
  ++next_;
  return &step;
}

Expected<FrontStep> ReplayFront::track(const CameraFrame* frame, double stamp) {
  (void)frame;
  auto recorded = next(/*flush=*/false, stamp);
  if (!recorded.ok()) return Error{recorded.error()};
  FrontStep step;
  step.result.status = (*recorded)->status;
  step.T_W_B = (*recorded)->T_W_B;
  return step;
}

Status ReplayFront::beginFlush(double stamp) {
  auto recorded = next(/*flush=*/true, stamp);
  if (!recorded.ok()) {
    if (status_) status_ = Error{recorded.error()};
    return Error{recorded.error()};
  }
  return Status::Ok();
}

std::optional<Submap> ReplayFront::takeWindowIfDue(double t) {
  (void)t;  // the recording says whether a window was due at this step
  if (next_ == 0) return std::nullopt;
  std::optional<Submap>& window = log_.steps[next_ - 1].window;
  if (!window) return std::nullopt;
  std::optional<Submap> out = std::move(window);
  window.reset();
  if (have_identity_) {
    out->header.agent = agent_;
    out->header.session = session_;
  }
  return out;
}

distill::MotionHint ReplayFront::motionHint() const {
  return next_ == 0 ? distill::MotionHint{} : log_.steps[next_ - 1].motion;
}

Status ReplayFront::finish(std::int64_t frames, std::int64_t lost) {
  (void)frames;
  (void)lost;
  if (status_ && !done()) status_ = Error{"tracking replay: steps of the recording were left over"};
  return status_;
}

}  // namespace hermes::agent
