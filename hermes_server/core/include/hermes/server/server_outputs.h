// Server outputs (DESIGN.md §5, §7): per-agent merged trajectories (TUM, world
// frame), the global map's landmarks as PLY, and the metrics fragment.
#pragma once

#include <array>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "hermes/core/global_pose.h"
#include "hermes/core/metrics.h"
#include "hermes/core/trajectory.h"
#include "hermes/server/server.h"

namespace hermes {
namespace server {

/// Keyframe poses of `agent` (all its anchored sessions) in the world frame,
/// sorted by stamp: T_W_C, or T_W_B = T_W_C * T_B_C^-1 when T_B_C is given.
Trajectory agentTrajectory(const GlobalMap& map, std::uint32_t agent,
                           const std::optional<SE3>& T_B_C = std::nullopt);

/// For every anchored trajectory: world <- odometry at its newest keyframe
/// (T_W_C * T_A_C^-1 there), keyed by (robot, session) - what each robot is told
/// after a merge (global_pose.h).
std::vector<std::pair<std::uint32_t, GlobalPoseUpdate>> globalPoseUpdates(const GlobalMap& map);

/// What the live outputs need from the merged map, copied after a merge so
/// that another thread can publish them while the next merge runs
/// (server_worker.h). Positions in the world frame.
struct MergedView {
  struct RobotPose {
    RobotId robot = 0;
    Uuid uuid{};
    GlobalPoseUpdate update;
  };
  std::uint64_t version = 0;                 ///< views published before this one + 1
  std::vector<RobotPose> poses;              ///< globalPoseUpdates of current sessions only
  std::map<RobotId, Trajectory> paths;       ///< agentTrajectory of every robot that has one
  std::vector<Vec3> landmarks;               ///< GlobalMap::landmarkPositionsWorld
  std::vector<RobotId> landmark_robots;      ///< the robot of each landmark (same order)
  std::vector<std::pair<Vec3, Vec3>> loops;  ///< accepted loops between anchored keyframes (camera centres)
  RunMetrics metrics;                        ///< mergeMetrics (the intake part is added when read)
};

/// The view of the server's map now: call from the thread that runs
/// process() (or while none runs); it takes Server::lockIntake() for the
/// bookkeeper's part.
MergedView mergedView(const Server& server);

/// Writes <dir>/agent_<robot>.tum for every anchored agent; returns the paths.
Expected<std::vector<std::string>> writeAgentTrajectories(
    const GlobalMap& map, const std::string& dir, const std::map<std::uint32_t, SE3>& T_B_C = {});

/// Display colour of a robot (RGB), the same in rviz (config/rviz/hermes.rviz
/// paths), the global map cloud and the plots: matplotlib's tab10 by robot id.
std::array<std::uint8_t, 3> robotColour(std::uint32_t robot);

/// PLY point cloud (x y z as float), ascii or binary little endian.
Status writePly(const std::string& path, const std::vector<Vec3>& points, bool binary);
/// Reads back what writePly wrote (either format).
Expected<std::vector<Vec3>> readPly(const std::string& path);

/// What the server holds for `robot` awaiting merge, into the agent's metrics
/// (held_submaps, held_bytes, held_bytes_peak; zeros when nothing ever was).
void fillHeldLoad(const Server& server, RobotId robot, AgentMetrics* metrics);
/// The robot's sessions, of them re-localised and reported as new robots
/// (bookkeeper.h), into the agent's metrics (sessions, relocalised, reported_new).
void fillSessions(const Bookkeeper& bookkeeper, RobotId robot, AgentMetrics* metrics);

/// The server's share of the metrics JSON: loops_accepted, loops_rejected,
/// agents_merged, timings_ms, frames_refused, relocalised, robots_new; per_agent
/// with keyframes/landmarks/bytes/submaps, the held load and the sessions. Both
/// parts below: read it from the thread that runs process(), or while none runs.
RunMetrics serverMetrics(const Server& server);
/// The merging thread's part: loops_accepted, loops_rejected, timings_ms.
RunMetrics mergeMetrics(const Server& server);
/// The intake part (with a merge thread running elsewhere: under
/// Server::lockIntake()): agents_merged, per_agent, bytes_total, frames_refused,
/// relocalised, robots_new.
void addIntakeMetrics(const Server& server, RunMetrics* m);

}  // namespace server
}  // namespace hermes
