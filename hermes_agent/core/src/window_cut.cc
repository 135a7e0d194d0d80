#include "hermes/agent/window_cut.h"

namespace hermes {

WindowCut::WindowCut(Tracker& tracker, const SubmapWindowParams& params) : tracker_(tracker), params_(params) {}

void WindowCut::setAgent(const Uuid& agent, std::uint32_t session) {
  header_.agent = agent;
  header_.session = session;
}

std::optional<Submap> WindowCut::takeWindowIfDue(double t) {
  const std::vector<Keyframe>& keyframes = tracker_.keyframes();
  if (keyframes.empty()) return std::nullopt;
  if (!started_) {
    started_ = true;
    last_t_ = keyframes.front().stamp;
  }
  const std::size_t last = tracker_.mappedKeyframes();  // a consistent point (see the header)
  if (t - last_t_ < params_.period_s || next_kf_ >= last) return std::nullopt;
  Submap s = buildWindow(keyframes, tracker_.landmarks(), tracker_.lostBefore(), next_kf_, last,
                         tracker_.intrinsics(), header_, params_);
  ++header_.seq;
  next_kf_ = last;
  last_t_ = t;
  health_ = tracker_.takeWindowHealth();
  return s;
}

distill::MotionHint WindowCut::motionHint() const {
  distill::MotionHint h = tracker_.motionHint();
  h.health = health_;
  return h;
}

void WindowCut::restart() {
  header_.seq = SubmapHeader{}.seq;  // a new session numbers its windows anew
  next_kf_ = 0;
  started_ = false;
  last_t_ = 0;
}

}  // namespace hermes
