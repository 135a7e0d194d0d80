// The map model shared by agent, distillation, wire format and server.
// A Submap is one agent's window of keyframes and landmarks (the unit that is
// distilled, encoded, sent, acknowledged and merged). Ids are stable within
// (agent uuid, session): an agent that restarts or resets starts a new session.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "hermes/core/geometry.h"

namespace hermes {

using KeyframeId = std::uint64_t;
using LandmarkId = std::uint64_t;
constexpr std::uint64_t kInvalidId = ~std::uint64_t{0};

/// 128-bit agent identity, random per robot install.
using Uuid = std::array<std::uint8_t, 16>;
std::string toString(const Uuid& id);
/// Parses the 32-hex-digit form (dashes allowed); returns false on bad input.
bool parseUuid(const std::string& text, Uuid* out);
/// Deterministic uuid from a seed (tests, simulations).
Uuid uuidFromSeed(std::uint64_t seed);
/// The uuid of the agent named `name` (the robot name; AgentPipeline's identity,
/// and how a server's key directory maps `<name>.key` to a uuid).
Uuid agentUuid(const std::string& name);

/// A 256-bit ORB descriptor.
using Descriptor = std::array<std::uint8_t, 32>;
int hammingDistance(const Descriptor& a, const Descriptor& b);

/// Globally unique keyframe key on the server: (agent, session, local id).
struct KeyframeKey {
  std::uint32_t agent = 0;    ///< server-assigned robot id
  std::uint32_t session = 0;  ///< agent session
  KeyframeId id = kInvalidId;
  bool operator==(const KeyframeKey& o) const {
    return agent == o.agent && session == o.session && id == o.id;
  }
  bool operator<(const KeyframeKey& o) const {
    if (agent != o.agent) return agent < o.agent;
    if (session != o.session) return session < o.session;
    return id < o.id;
  }
};

/// Pinhole intrinsics of the (undistorted / rectified) image the keypoints live in.
struct PinholeIntrinsics {
  double fx = 0, fy = 0, cx = 0, cy = 0;
  int width = 0, height = 0;
  Vec3 bearing(const Vec2& uv) const {
    return Vec3((uv.x() - cx) / fx, (uv.y() - cy) / fy, 1.0).normalized();
  }
  Vec2 project(const Vec3& p_C) const {
    return Vec2(fx * p_C.x() / p_C.z() + cx, fy * p_C.y() / p_C.z() + cy);
  }
  bool inImage(const Vec2& uv, double border = 0.0) const {
    return uv.x() >= border && uv.y() >= border && uv.x() < width - border &&
           uv.y() < height - border;
  }
  /// Column in the right image of a rectified stereo pair (or the virtual right
  /// camera of RGB-D) of left column u at `depth`, `baseline` [m] apart; at
  /// least 0. -1 without a depth.
  double rightColumn(double u, double depth, double baseline) const {
    return depth > 0 ? std::max(0.0, u - fx * baseline / depth) : -1.0;
  }
};

/// An undistorted keypoint of a keyframe.
struct Keypoint {
  float u = 0, v = 0;     ///< pixel in the undistorted/rectified image [px]
  std::uint8_t octave = 0;///< pyramid level it was detected at
  float depth = 0;        ///< metric depth from stereo / RGB-D, 0 = unknown [m]
};

/// (keyframe, keypoint index) seeing a landmark.
struct Observation {
  KeyframeId keyframe = kInvalidId;
  std::uint32_t keypoint = 0;
};

/// Relative pose between two keyframes with its information (6x6, [rho; phi]).
struct OdometryEdge {
  KeyframeId from = kInvalidId;
  KeyframeId to = kInvalidId;
  SE3 T_from_to;       ///< pose of `to` expressed in `from`
  Mat6 information = Mat6::Identity();
};

struct Keyframe {
  KeyframeId id = kInvalidId;
  double stamp = 0;          ///< [s]
  SE3 T_A_C;                 ///< agent (odometry) frame <- camera
  std::uint32_t camera_id = 0;
  std::vector<Keypoint> keypoints;
  std::vector<Descriptor> descriptors;    ///< one per keypoint
  std::vector<LandmarkId> keypoint_landmark;  ///< per keypoint, kInvalidId if none
  /// Tracking was lost between the previous keyframe of this session and this
  /// one (a relocalisation): the odometry across that gap is unreliable.
  bool lost_before = false;
};

struct Landmark {
  LandmarkId id = kInvalidId;
  Vec3 p_A = Vec3::Zero();   ///< position in the agent frame [m]
  Descriptor descriptor{};   ///< representative descriptor
  std::vector<Observation> observations;
};

/// Identity and ordering of a submap on the uplink.
struct SubmapHeader {
  Uuid agent{};
  std::uint32_t session = 0;
  std::uint64_t seq = 0;
  double t_start = 0, t_end = 0;  ///< window span [s]
};

/// One window of an agent's map, the unit of distillation and transmission.
///
/// Keyframe extensions: a keyframe stamped before header.t_start is not part of
/// the window but extends a keyframe an earlier submap of the same session
/// carried (same id): it brings keypoints only (descriptor + depth, no landmark
/// link, no landmark observes it, no odometry edge names it), which the server
/// appends to the stored keyframe. The agent sends them once a window planned
/// before the link was measured turns out to have had room for them.
struct Submap {
  SubmapHeader header;
  std::vector<PinholeIntrinsics> cameras;  ///< indexed by Keyframe::camera_id
  std::vector<Keyframe> keyframes;         ///< ordered by stamp (extensions first)
  std::vector<Landmark> landmarks;
  std::vector<OdometryEdge> odometry;      ///< between consecutive kept keyframes

  /// Checks internal consistency (ids unique, observations point to existing
  /// keyframes/keypoints, descriptor counts, camera ids). Returns an empty
  /// string when valid, otherwise a message naming the first problem.
  std::string validate() const;
  std::size_t observationCount() const;
  /// True for a keyframe extension (stamped before the window's start).
  bool isExtension(const Keyframe& kf) const { return kf.stamp < header.t_start; }
  /// Keyframes of the window itself (extensions not counted).
  std::size_t windowKeyframeCount() const;
};

}  // namespace hermes
