#include "hermes/agent/odometry_corruption.h"

#include <algorithm>
#include <cmath>
#include <unordered_map>

namespace hermes::agent {

Status OdometryCorruptionParams::read(const Config& c) {
  for (Status s : {c.get("corrupt.agent", &agent), c.getChoice("corrupt.kind", {"none", "jump", "drift"}, &kind),
                   c.get("corrupt.at_s", &at_s), c.get("corrupt.jump_m", &jump_m),
                   c.get("corrupt.jump_deg", &jump_deg), c.get("corrupt.noticed", &noticed),
                   c.get("corrupt.drift_fraction", &drift_fraction),
                   c.get("corrupt.drift_duration_s", &drift_duration_s)})
    if (!s) return s;
  return validate();
}

void OdometryCorruptionParams::write(ConfigWriter* w) const {
  w->set("corrupt.agent", agent);
  w->set("corrupt.kind", kind);
  w->set("corrupt.at_s", at_s);
  w->set("corrupt.jump_m", jump_m);
  w->set("corrupt.jump_deg", jump_deg);
  w->set("corrupt.noticed", noticed);
  w->set("corrupt.drift_fraction", drift_fraction);
  w->set("corrupt.drift_duration_s", drift_duration_s);
}

Status OdometryCorruptionParams::validate() const {
  if (kind != "none" && kind != "jump" && kind != "drift")
    return Error{"corrupt.kind must be none, jump or drift (got '" + kind + "')"};
  if (kind != "none" && agent.empty()) return Error{"corrupt.kind " + kind + " needs corrupt.agent"};
  for (double v : {at_s, jump_m, jump_deg, drift_fraction, drift_duration_s})
    if (!std::isfinite(v)) return Error{"corrupt.*: values must be finite"};
  if (at_s < 0 || drift_duration_s < 0 || drift_fraction < 0)
    return Error{"corrupt.at_s, drift_duration_s and drift_fraction must be >= 0"};
  return Status::Ok();
}

bool OdometryCorruptor::noticedJumpAt(double stamp) const {
  return params_.kind == "jump" && params_.noticed && started_ && !jumped_ &&
         stamp - first_stamp_ >= params_.at_s;
}

SE3 OdometryCorruptor::onFrame(double stamp, const SE3& T_W_B) {
  if (!started_) {
    started_ = true;
    first_stamp_ = stamp;
  }
  const double t = stamp - first_stamp_;
  if (params_.kind == "jump" && !jumped_ && t >= params_.at_s) {
    jumped_ = true;
    const Vec3 p = T_W_B.translation();
    const SE3 R(Quat(Eigen::AngleAxisd(params_.jump_deg * M_PI / 180.0, Vec3::UnitY())), Vec3::Zero());
    // Rotate about the current position, then shift along x.
    C_ = SE3(Quat::Identity(), p + Vec3(params_.jump_m, 0, 0)) * R * SE3(Quat::Identity(), -p);
    history_.emplace_back(stamp, C_);
  } else if (params_.kind == "drift" && t >= params_.at_s &&
             t <= params_.at_s + params_.drift_duration_s) {
    if (have_prev_) travelled_m_ += (T_W_B.translation() - prev_T_W_B_.translation()).norm();
    C_ = SE3(Quat::Identity(), Vec3(params_.drift_fraction * travelled_m_, 0, 0));
    history_.emplace_back(stamp, C_);
  }
  prev_T_W_B_ = T_W_B;
  have_prev_ = true;
  return C_;
}

SE3 OdometryCorruptor::at(double stamp) const {
  auto it = std::upper_bound(history_.begin(), history_.end(), stamp,
                             [](double s, const std::pair<double, SE3>& h) { return s < h.first; });
  if (it == history_.begin()) return SE3();
  return std::prev(it)->second;
}

void OdometryCorruptor::apply(Submap* w) const {
  if (history_.empty() || w->keyframes.empty()) return;
  std::unordered_map<KeyframeId, std::size_t> index;
  for (std::size_t i = 0; i < w->keyframes.size(); ++i) {
    Keyframe& kf = w->keyframes[i];
    kf.T_A_C = at(kf.stamp) * kf.T_A_C;
    index[kf.id] = i;
  }
  for (Landmark& l : w->landmarks) {
    double stamp = w->keyframes.front().stamp;
    KeyframeId first = kInvalidId;
    for (const Observation& o : l.observations) first = std::min(first, o.keyframe);
    if (auto it = index.find(first); it != index.end()) stamp = w->keyframes[it->second].stamp;
    l.p_A = at(stamp) * l.p_A;
  }
  for (OdometryEdge& e : w->odometry) {
    auto a = index.find(e.from), b = index.find(e.to);
    if (a == index.end() || b == index.end()) continue;
    e.T_from_to = w->keyframes[a->second].T_A_C.inverse() * w->keyframes[b->second].T_A_C;
  }
}

}  // namespace hermes::agent
