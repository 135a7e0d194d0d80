// Generalized cameras ("rigs") built from keyframes of one agent's odometry,
// and descriptor matching from one rig to another (used by the 17-point loop
// closer, DESIGN.md §5).
#pragma once

#include <string>
#include <vector>

#include "hermes/core/config.h"
#include "hermes/core/geometry.h"
#include "hermes/core/map_types.h"
#include "hermes/core/status.h"

namespace hermes {
namespace server {

/// A multi-camera rig: keyframes[0] is the reference keyframe; each keyframe is
/// one camera with its metric offset T_ref_C from odometry.
struct Rig {
  std::vector<const Keyframe*> keyframes;   ///< not owned; must outlive the rig
  std::vector<PinholeIntrinsics> intrinsics;///< one per keyframe
  std::vector<SE3> T_ref_C;                 ///< reference keyframe <- camera k
};

/// Builds a rig from a reference keyframe and its neighbours (all poses T_A_C in
/// one agent frame). `cameras` is indexed by Keyframe::camera_id (Submap::cameras).
/// Errors name the keyframe whose data is inconsistent.
Expected<Rig> makeRig(const Keyframe& reference, const std::vector<const Keyframe*>& neighbours,
                      const std::vector<PinholeIntrinsics>& cameras);

struct RigMatchingParams {
  int max_hamming = 60;          ///< accept a match only below this distance [bits]
  double ratio = 0.8;            ///< best < ratio * second best (within one camera pair)
  bool cross_check = true;       ///< mutual best within the camera pair
  int max_matches_per_keypoint = 2;  ///< cap: a query keypoint keeps its k best cameras

  Status read(const Config& config, const std::string& prefix);
  void write(ConfigWriter* writer, const std::string& prefix) const;
  Status validate() const;
};

/// One putative correspondence: keypoint kp_q of rig-Q camera cam_q <-> keypoint
/// kp_c of rig-C camera cam_c.
struct RigMatch {
  int cam_q = 0;
  int kp_q = 0;
  int cam_c = 0;
  int kp_c = 0;
  int distance = 0;
};

/// Brute-force Hamming matching between every camera pair of the two rigs with
/// ratio test and cross check per camera pair (the same 3D point appears in
/// several keyframes of a rig, so a rig-wide ratio test would reject it), then
/// at most max_matches_per_keypoint matches per query keypoint (lowest distance).
std::vector<RigMatch> matchRigs(const Rig& query, const Rig& candidate,
                                const RigMatchingParams& params);

}  // namespace server
}  // namespace hermes
