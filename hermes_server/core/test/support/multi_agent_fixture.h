// Multi-agent fixture for the server pipeline: agents move along real EuRoC
// ground-truth trajectories through one shared hall of 3D landmarks (each with
// one fixed random descriptor, a few bits flipped per observation); keyframes
// every `keyframe_period_s` observe the projections (pixel noise); each agent's
// poses are expressed in its own frame A_i (random T_W_Ai, small odometry drift)
// and split into submaps, encoded as wire frames.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "hermes/core/map_types.h"
#include "hermes/core/status.h"
#include "hermes/core/trajectory.h"

namespace hermes {
namespace server {
namespace fixture {

struct AgentSpec {
  std::string gt_file;      ///< TUM ground truth (body poses T_W_B)
  double from_s = 0, to_s = 20;  ///< span relative to the file's first stamp [s]
  double reset_at_s = -1;   ///< >= 0: start a new session (ids from 0, new frame) here
};

struct Options {
  int keypoints = 200;
  double keyframe_period_s = 0.5;
  double submap_s = 5.0;
  double pixel_noise = 0.5;
  double drift_m = 0.002, drift_rad = 0.0005;  ///< per keyframe step (1 sigma)
  int bit_flips = 3;
  int landmarks_per_keyframe = 40;  ///< seeded in the view of every agent keyframe
  std::uint64_t seed = 7;
};

struct Agent {
  Uuid uuid{};
  Trajectory gt_body;               ///< T_W_B at the keyframe stamps
  std::vector<Submap> submaps;      ///< in sending order
  std::vector<std::vector<std::uint8_t>> frames;  ///< encoded submaps
  int keyframes = 0;
};

struct Fixture {
  std::vector<Agent> agents;
  SE3 T_B_C;
  PinholeIntrinsics camera;
  std::size_t landmarks = 0;
};

Expected<Fixture> makeFixture(const std::vector<AgentSpec>& specs, const Options& options);

/// Two robots in one hall: MH_01 and MH_02 (ground truth in
/// config/trajectories) over their first `seconds`, `keypoints` per keyframe.
Expected<Fixture> hallPair(double seconds, int keypoints);

/// Three robots in one hall, built once: MH_01 over its first 15 s, MH_02 over
/// 16 s with a second session from 8 s, MH_03 over 15 s (default options).
const Fixture& hallTrio();

/// The agents' frames round-robin (first of each, second of each, ...), as sent.
std::vector<const std::vector<std::uint8_t>*> roundRobin(const Fixture& fx);

}  // namespace fixture
}  // namespace server
}  // namespace hermes
