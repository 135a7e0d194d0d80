// Test hook (offline runner, `--set corrupt.*`): corrupts one agent's odometry as
// a relocalisation error (a jump) or a textureless stretch (a drift) would, while
// everything the agent observes stays right, so its loops to the others stay
// right too. A jump is a relocalisation error: by default (`noticed`) the
// tracker counts the frame as lost, as it does when it really relocalises, so
// the odometry edge across it is weakened (odometry.lost_inflation) while its
// pose is still wrong; with noticed = false the jump is silent. A drift is
// always silent. This is how the server's merge is tested against odometry it
// cannot trust.
//
// The corruption is a transform C(t) of the odometry frame W applied on the left
// of every pose from time t (T_W_B' = C(t) T_W_B, T_A_C' = C(t) T_A_C; a landmark
// moves with the keyframe that first sees it in the window; odometry edges are
// recomputed from the corrupted keyframe poses):
//   jump:  from at_s on, C = a rotation of jump_deg about W's y axis (the first
//          camera's down axis: a yaw for a level camera) through the position at
//          the jump, followed by jump_m along W's x axis;
//   drift: from at_s for drift_duration_s, C = a translation along W's x axis of
//          drift_fraction x the distance travelled since at_s; held afterwards.
// t is the time since the agent's first frame [s].
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "hermes/core/config.h"
#include "hermes/core/map_types.h"

namespace hermes::agent {

struct OdometryCorruptionParams {
  std::string agent;              ///< agent (dataset) name to corrupt; empty = none
  std::string kind = "none";      ///< none | jump | drift
  double at_s = 0;                ///< [s] since the agent's first frame
  double jump_m = 0.5;            ///< [m]
  double jump_deg = 10;           ///< [deg]
  bool noticed = true;            ///< jump: the tracker counts a lost frame there
  double drift_fraction = 0.03;   ///< error per distance travelled (unitless)
  double drift_duration_s = 30;   ///< [s]

  /// Keys under "corrupt.".
  Status read(const Config& config);
  void write(ConfigWriter* writer) const;
  Status validate() const;
  bool active() const { return kind != "none" && !agent.empty(); }
};

class OdometryCorruptor {
 public:
  explicit OdometryCorruptor(OdometryCorruptionParams params) : params_(std::move(params)) {}

  /// Before a frame is tracked: a noticed jump happens at this frame (the
  /// tracker should count it as a relocalisation).
  bool noticedJumpAt(double stamp) const;
  /// Every tracked frame, in time order: its uncorrupted pose T_W_B; returns C(t).
  SE3 onFrame(double stamp, const SE3& T_W_B);
  /// C at a tracked frame's stamp (the last frame at or before it; identity before any).
  SE3 at(double stamp) const;
  /// Corrupts a window's keyframes, landmarks and odometry edges.
  void apply(Submap* window) const;

 private:
  OdometryCorruptionParams params_;
  double first_stamp_ = 0;
  bool started_ = false;
  bool have_prev_ = false;
  SE3 prev_T_W_B_;
  double travelled_m_ = 0;  ///< since at_s, within the drift's duration
  bool jumped_ = false;
  SE3 C_;
  std::vector<std::pair<double, SE3>> history_;  ///< (stamp, C) of every frame C changed at
};

}  // namespace hermes::agent
