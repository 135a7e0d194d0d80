// A robot's place in the global map (issue 19 item 4): after each merge the server
// tells every anchored robot world <- odometry at its newest merged keyframe (the
// correction the pose graph made there). The robot applies it to its own odometry
// to know where it is in the world between merges: T_W_B = T_W_O * T_O_B.
#pragma once

#include <cstdint>
#include <optional>

#include "hermes/core/geometry.h"
#include "hermes/core/status.h"

namespace hermes {

/// What the server sends a robot after a merge.
struct GlobalPoseUpdate {
  std::uint32_t session = 0;   ///< the robot's session the keyframe belongs to
  double keyframe_stamp = 0;   ///< stamp of the keyframe it was taken at [s]
  std::uint64_t keyframes = 0; ///< merged keyframes of that session (for display)
  SE3 T_W_O;                   ///< world <- the robot's odometry frame
  /// Finite transform and stamp, unit rotation (decoders check this).
  Status validate() const;
};

/// The robot side: keeps the newest update of its current session.
class GlobalPoseState {
 public:
  /// Takes `u` when it belongs to `current_session` and is not older (by keyframe
  /// stamp) than what is held; false otherwise (another session, stale, invalid).
  bool update(const GlobalPoseUpdate& u, std::uint32_t current_session, double now);
  /// A new session (map reset): what was known no longer applies.
  void reset() { held_.reset(); }
  const std::optional<GlobalPoseUpdate>& latest() const { return held_; }
  /// Receive time of the latest update [s] (nullopt before one).
  std::optional<double> receivedAt() const { return held_ ? std::optional<double>(received_at_) : std::nullopt; }
  std::uint64_t updates() const { return updates_; }
  /// T_W_X for a pose T_O_X in the odometry frame (nullopt before the first update).
  std::optional<SE3> inWorld(const SE3& T_O_X) const;

 private:
  std::optional<GlobalPoseUpdate> held_;
  double received_at_ = 0;
  std::uint64_t updates_ = 0;
};

}  // namespace hermes
