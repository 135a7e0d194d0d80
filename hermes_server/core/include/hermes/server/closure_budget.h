// A budget on the loop closures one merge verifies (server.map.closure_budget).
// A closure (17-point verification of one candidate) costs 40-150 ms; with 20
// robots a merge proposes ~30 of them and the server falls behind the swarm
// (DESIGN.md §9). Most of them tie two trajectories that hundreds of loops tie
// already. Under a budget the closures are taken round robin over the pairs of
// trajectories they would tie, pairs with fewer accepted loops first: a pair not
// tied yet (a robot still to be placed, two groups still apart) never waits
// behind a pair that is tied, and every pair still gets some of the budget.
// The closures left over are not dropped: the map manager keeps them
// (map.deferred_closures) and verifies them, a budget at a time, while no
// submap waits (Server::process), so a submap's merge stays short and the loops
// still come when the server has time.
#pragma once

#include <map>
#include <utility>
#include <vector>

#include "hermes/server/global_map.h"

namespace hermes {
namespace server {

/// Two trajectories, smaller first (a loop ties them both ways).
using TrajectoryPair = std::pair<TrajectoryId, TrajectoryId>;

TrajectoryPair makeTrajectoryPair(TrajectoryId a, TrajectoryId b);
/// The pair of the trajectories of two keyframes.
TrajectoryPair pairOf(const KeyframeKey& a, const KeyframeKey& b);
/// Accepted loops per trajectory pair.
std::map<TrajectoryPair, int> acceptedLoopsPerPair(const std::vector<LoopEdge>& loops);

/// Which closures to verify: `pairs[i]` is the trajectory pair of closure i (in
/// the order proposed), `accepted` the loops accepted so far per pair (missing =
/// 0). Returns one flag per closure; at most `budget` are set (all when budget
/// <= 0 or there are no more closures than that). Pairs are visited in order of
/// accepted loops (ties: the pair's first closure first), one closure per pair
/// per round, each pair's closures in the order proposed.
std::vector<char> chooseWithinBudget(const std::vector<TrajectoryPair>& pairs,
                                     const std::map<TrajectoryPair, int>& accepted, int budget);

}  // namespace server
}  // namespace hermes
