#include "hermes/agent/tracking_source.h"

#include <string>

namespace hermes::agent {

Expected<const TrackingStep*> ReplayTracker::next(bool flush, double stamp) {
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

std::optional<Submap> ReplayTracker::takeWindowIfDue(double t) {
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

distill::MotionHint ReplayTracker::motionHint() const {
  return next_ == 0 ? distill::MotionHint{} : log_.steps[next_ - 1].motion;
}

}  // namespace hermes::agent
