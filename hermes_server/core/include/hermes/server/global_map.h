// The server's global map (DESIGN.md §5): every merged trajectory (agent,
// session) with its keyframes, landmarks and odometry in its own agent frame A,
// its anchoring T_W_A once tied to the world, the optimised keyframe poses T_W_C,
// and the loop edges. Landmarks follow their anchor keyframe (the keyframe of
// their first observation): p_W = T_W_C(anchor) * p_C.
//
// Binary file (save/load): "HGMP" magic, version 4, every trajectory field by field
// (keyframes with keypoints, descriptors and landmark links, landmarks with their
// anchors and observations, odometry edges), loop edges with their PCM verdicts,
// inlier counts and kept inlier keypoint pairs, CRC-32 of everything before it. Other versions are
// refused with a message naming both. Lossless: a map saved and loaded
// holds exactly what it held (the server checkpoint embeds it).
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "hermes/core/geometry.h"
#include "hermes/core/map_types.h"
#include "hermes/core/status.h"

namespace hermes {
namespace server {

using TrajectoryId = std::pair<std::uint32_t, std::uint32_t>;  ///< (agent, session)

struct StoredKeyframe {
  Keyframe keyframe;          ///< as received (T_A_C in the agent frame)
  PinholeIntrinsics camera;
  SE3 T_W_C;                  ///< valid when the trajectory is anchored
};

struct StoredLandmark {
  Landmark landmark;          ///< as first received (p_A), observations accumulated
  KeyframeId anchor = kInvalidId;
  Vec3 p_anchor = Vec3::Zero();  ///< position in the anchor camera frame
};

struct TrajectoryMap {
  std::uint32_t agent = 0, session = 0;
  Uuid uuid{};
  bool anchored = false;
  SE3 T_W_A;                  ///< initial anchoring (keyframe poses are refined after)
  std::map<KeyframeId, StoredKeyframe> keyframes;
  std::map<LandmarkId, StoredLandmark> landmarks;
  std::map<std::pair<KeyframeId, KeyframeId>, OdometryEdge> odometry;
};

/// One inlier correspondence of a loop closure, kept for the map-consistency
/// measure's cross-robot ties (map_consistency.h): keypoint kp_a of keyframe kf_a (in the trajectory of
/// LoopEdge::a; the rig's keyframe, not necessarily a itself) sees the same
/// point as keypoint kp_b of keyframe kf_b (trajectory of LoopEdge::b).
struct LoopMatch {
  KeyframeId kf_a = kInvalidId;
  std::uint32_t kp_a = 0;
  KeyframeId kf_b = kInvalidId;
  std::uint32_t kp_b = 0;
  bool operator==(const LoopMatch& o) const {
    return kf_a == o.kf_a && kp_a == o.kp_a && kf_b == o.kf_b && kp_b == o.kp_b;
  }
};

struct LoopEdge {
  std::uint64_t id = 0;
  KeyframeKey a, b;           ///< a = query, b = candidate
  SE3 T_a_b;
  Mat6 information = Mat6::Identity();
  Mat6 covariance = Mat6::Identity();
  bool accepted = false;      ///< by PCM (latest run)
  int inliers = 0;            ///< geometric inliers of the loop closure
  int depth_inliers = 0;      ///< of which with a measured depth in at least one view
  /// Inlier keypoint pairs kept (server.map.ties_per_loop, evenly spaced).
  std::vector<LoopMatch> matches;
};

class GlobalMap {
 public:
  std::map<TrajectoryId, TrajectoryMap> trajectories;
  std::vector<LoopEdge> loops;

  const StoredKeyframe* keyframe(const KeyframeKey& key) const;
  StoredKeyframe* keyframe(const KeyframeKey& key);
  const TrajectoryMap* trajectory(std::uint32_t agent, std::uint32_t session) const;
  std::size_t keyframeCount() const;
  std::size_t landmarkCount() const;

  /// World positions of the landmarks of anchored trajectories; with `robots`,
  /// also the robot each one belongs to (same order), e.g. to colour by robot.
  std::vector<Vec3> landmarkPositionsWorld(std::vector<std::uint32_t>* robots = nullptr) const;
  /// Re-derives a landmark's anchor (first observation with a stored keyframe).
  static void anchorLandmark(const TrajectoryMap& traj, StoredLandmark* lm);

  std::vector<std::uint8_t> toBytes() const;
  static Expected<GlobalMap> fromBytes(const std::vector<std::uint8_t>& bytes,
                                       const std::string& origin);
  Status save(const std::string& path) const;
  static Expected<GlobalMap> load(const std::string& path);
};

}  // namespace server
}  // namespace hermes
