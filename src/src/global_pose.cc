// The robot's place in the global map: the server's world <- odometry correction.
#include "hermes/core/global_pose.h"

#include <cmath>

namespace hermes {

Status GlobalPoseUpdate::validate() const {
  if (!std::isfinite(keyframe_stamp)) return Error{"global pose: keyframe stamp is not finite"};
  if (!T_W_O.translation().allFinite() || !T_W_O.quat().coeffs().allFinite())
    return Error{"global pose: world <- odom transform is not finite"};
  if (std::abs(T_W_O.quat().norm() - 1.0) > 1e-6)
    return Error{"global pose: rotation is not a unit quaternion (norm " +
                 std::to_string(T_W_O.quat().norm()) + ")"};
  return Status::Ok();
}

bool GlobalPoseState::update(const GlobalPoseUpdate& u, std::uint32_t current_session, double now) {
  if (u.session != current_session || !u.validate()) return false;
  if (held_ && u.keyframe_stamp < held_->keyframe_stamp) return false;
  held_ = u;
  received_at_ = now;
  ++updates_;
  return true;
}

std::optional<SE3> GlobalPoseState::inWorld(const SE3& T_O_X) const {
  if (!held_) return std::nullopt;
  return held_->T_W_O * T_O_X;
}

}  // namespace hermes
