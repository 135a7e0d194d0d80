// Server outputs (DESIGN.md §5, §7): per-agent merged trajectories (TUM, world
// frame), the global map's landmarks as PLY, and the metrics fragment.
#pragma once

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

/// Writes <dir>/agent_<robot>.tum for every anchored agent; returns the paths.
Expected<std::vector<std::string>> writeAgentTrajectories(
    const GlobalMap& map, const std::string& dir, const std::map<std::uint32_t, SE3>& T_B_C = {});

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
/// with keyframes/landmarks/bytes/submaps, the held load and the sessions.
RunMetrics serverMetrics(const Server& server);

}  // namespace server
}  // namespace hermes
