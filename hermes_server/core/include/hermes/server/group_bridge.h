// PCM across tie groups (DESIGN.md §5). Per-pair PCM (pcm.h) accepts loops
// between two trajectories only as a consistent set of at least
// min_clique_size (3): one right loop alone cannot be told from a wrong one. In
// a swarm a robot often meets several others only briefly, 1-2 right loops to
// each: every pair stays below the threshold and the robot is never placed (at
// 20 robots, 15 merged; the loops between the two groups were 1-2 per pair).
//
// Trajectories tied by accepted loops form a group, and within a group the
// relative pose of any two keyframes is known through those loops: chain ->
// tie loop -> chain -> ... -> chain (one tie loop per hop along a shortest path
// of trajectories; per hop the tie with the smallest covariance), composed with
// first-order covariance propagation like the odometry. So the loops between two
// groups can be judged together by the same cycle test as a pair's: the largest
// mutually consistent set between two groups is accepted when it holds at least
// bridge_min_loops loops over at least two trajectory pairs (one pair alone is
// per-pair PCM's case, already decided). The two groups become one and the step
// repeats, largest bridge first, until nothing joins.
#pragma once

#include <cstdint>
#include <map>
#include <set>
#include <utility>
#include <vector>

#include "hermes/server/global_map.h"
#include "hermes/server/pcm.h"

namespace hermes {
namespace server {

/// Groups of trajectories tied by accepted loops, and the relative pose of two
/// keyframes of one group through them.
class TieGroups {
 public:
  using Trajectory = std::pair<std::uint32_t, std::uint32_t>;  ///< (agent, session)

  /// `odometry` answers within one trajectory (OdometryChain::query()).
  explicit TieGroups(OdometryQuery odometry);
  /// An accepted loop; one within a trajectory does not tie anything.
  void tie(const LoopCandidate& loop);
  /// The group's representative (the trajectory itself when not tied).
  Trajectory group(const Trajectory& t) const;
  /// T_from_to through the odometry and the ties; an error across groups.
  Expected<RelativePose> relative(const KeyframeKey& from, const KeyframeKey& to) const;
  OdometryQuery query() const;

 private:
  /// Loops (oriented from `from`'s trajectory) of a shortest path of ties.
  Expected<std::vector<LoopCandidate>> path(const Trajectory& from, const Trajectory& to) const;

  OdometryQuery odometry_;
  std::map<Trajectory, std::map<Trajectory, LoopCandidate>> ties_;  ///< best tie per neighbour, oriented
  mutable std::map<Trajectory, Trajectory> parent_;                 ///< union-find
};

struct BridgeResult {
  std::vector<std::uint64_t> accepted;  ///< loops accepted as bridges
  int bridges = 0;                      ///< group pairs joined
  long pairs_computed = 0;              ///< cycle distances computed
  int odometry_failures = 0;            ///< loop pairs without a path (counted inconsistent)
};

/// The loops of `loops` not in `accepted` that bridge groups (see above); the
/// groups are those the `accepted` loops tie. Off when params.bridge_min_loops is 0.
BridgeResult bridgeTieGroups(const std::vector<LoopCandidate>& loops,
                             const std::set<std::uint64_t>& accepted,
                             const OdometryQuery& odometry, const PcmParams& params);

/// The PCM candidate of a stored loop.
LoopCandidate loopCandidate(const LoopEdge& e);

/// Estimates of T_W_A for the unanchored trajectory `t` from the accepted loops
/// of the other unanchored members of its tie group to anchored trajectories,
/// each carried to `t` through the group's ties (its own loops are not included:
/// the map manager counts them directly).
std::vector<SE3> groupAnchorEstimates(const GlobalMap& map, const TieGroups& groups,
                                      const TrajectoryMap& t);

}  // namespace server
}  // namespace hermes
