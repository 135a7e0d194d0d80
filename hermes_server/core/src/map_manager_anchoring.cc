// MapManager, consistency and anchoring (map_manager.h): PCM over every loop
// (tie groups, the PCM cache), the world trajectory and the trajectories tied
// to it by min_world_loops accepted loops.
#include <algorithm>
#include <cmath>
#include <iterator>
#include <map>

#include "hermes/server/map_manager.h"
#include "map_manager_detail.h"

namespace hermes {
namespace server {

using map_manager_detail::Clock;
using map_manager_detail::keyOf;
using map_manager_detail::msSince;

void MapManager::runPcm() {
  std::vector<LoopCandidate> candidates;
  for (const LoopEdge& e : map_.loops) candidates.push_back(loopCandidate(e));
  if (chain_.revision() != pcm_chain_revision_) {
    pcm_cache_.clear();
    pcm_chain_revision_ = chain_.revision();
  }
  const PcmResult r = selectConsistentLoops(candidates, chain_.query(), params_.pcm, &pcm_cache_);
  std::set<std::uint64_t> accepted(r.accepted.begin(), r.accepted.end());
  // Loops that no pair holds enough of, consistent across tied groups (group_bridge.h).
  const BridgeResult b = bridgeTieGroups(candidates, accepted, chain_.query(), params_.pcm);
  accepted.insert(b.accepted.begin(), b.accepted.end());
  loops_bridged_ = static_cast<int>(b.accepted.size());
  for (LoopEdge& e : map_.loops) {
    const bool now = accepted.count(e.id) > 0;
    if (now != e.accepted) touched_.insert(e.a), touched_.insert(e.b);
    e.accepted = now;
  }
  if (accepted != accepted_) graph_dirty_ = true;
  accepted_ = std::move(accepted);
}

void MapManager::anchorTrajectory(TrajectoryMap* t, const SE3& T_W_A, SessionAnchor by) {
  t->anchored = true;
  t->T_W_A = T_W_A;
  for (auto& [id, kf] : t->keyframes) {
    kf.T_W_C = T_W_A * kf.keyframe.T_A_C;
    touched_.insert(keyOf(*t, id));
  }
  if (bookkeeper_) (void)bookkeeper_->markSessionAnchored(t->agent, t->session, by, T_W_A);
  graph_dirty_ = true;
}

bool MapManager::updateAnchoring(const std::function<double(RobotId)>& credibility) {
  if (!bookkeeper_) return false;
  std::unique_lock<std::mutex> shared;  // see setBookkeeperLock()
  if (bookkeeper_lock_) shared = std::unique_lock<std::mutex>(*bookkeeper_lock_);
  bool changed = false;
  // Groups of robots tied by verified inter-robot loops (union-find), built on
  // the first question (selectWorld asks only until the world is fixed).
  std::map<RobotId, RobotId> parent;
  const auto root = [&parent](RobotId r) {
    while (parent.count(r) && parent[r] != r) r = parent[r];
    return r;
  };
  bool grouped = false;
  const auto group = [&](RobotId r) -> std::size_t {
    if (!grouped) {
      grouped = true;
      for (const LoopEdge& e : map_.loops) {
        if (!e.accepted || e.a.agent == e.b.agent) continue;
        parent.emplace(e.a.agent, e.a.agent);
        parent.emplace(e.b.agent, e.b.agent);
        parent[root(e.a.agent)] = root(e.b.agent);
      }
    }
    std::size_t n = 0;
    const RobotId mine = root(r);
    for (const auto& [robot, up] : parent) n += root(robot) == mine ? 1 : 0;
    return std::max<std::size_t>(n, 1);
  };
  const auto world = bookkeeper_->selectWorld(credibility, group);
  if (!world) return false;
  // The world trajectory is fixed once: a later session of the world robot (it
  // restarted or reset its map) is anchored by loops like any other trajectory,
  // never put at the origin.
  if (!world_traj_) {
    auto wt = map_.trajectories.find({*world, bookkeeper_->worldSession().value_or(0)});
    if (wt != map_.trajectories.end() && !wt->second.anchored) {
      anchorTrajectory(&wt->second, SE3::identity(), SessionAnchor::kWorld);
      world_traj_ = wt->first;
      changed = true;
    }
  }
  std::optional<TieGroups> ties;  // of the accepted loops, built when a trajectory needs them
  for (bool progress = true; progress;) {
    progress = false;
    for (auto& [tid, t] : map_.trajectories) {
      if (t.anchored) continue;
      std::vector<SE3> estimates;
      for (const LoopEdge& e : map_.loops) {
        if (!e.accepted) continue;
        const bool a_here = e.a.agent == t.agent && e.a.session == t.session;
        const bool b_here = e.b.agent == t.agent && e.b.session == t.session;
        if (a_here == b_here) continue;
        const KeyframeKey other = a_here ? e.b : e.a;
        const TrajectoryMap* ot = map_.trajectory(other.agent, other.session);
        if (!ot || !ot->anchored) continue;
        const StoredKeyframe* ok = map_.keyframe(other);
        const StoredKeyframe* mine = map_.keyframe(a_here ? e.a : e.b);
        const SE3 T_W_Cmine = a_here ? ok->T_W_C * e.T_a_b.inverse() : ok->T_W_C * e.T_a_b;
        estimates.push_back(T_W_Cmine * mine->keyframe.T_A_C.inverse());
      }
      if (static_cast<int>(estimates.size()) < params_.min_world_loops) {
        // Too few of its own: those of its tie group's other members (bridged groups).
        if (!ties) {
          ties.emplace(chain_.query());
          for (const LoopEdge& e : map_.loops)
            if (e.accepted) ties->tie(loopCandidate(e));
        }
        const std::vector<SE3> more = groupAnchorEstimates(map_, *ties, t);
        estimates.insert(estimates.end(), more.begin(), more.end());
      }
      if (static_cast<int>(estimates.size()) < params_.min_world_loops) continue;
      // Medoid of the estimates (robust to a residual bad loop).
      std::size_t best = 0;
      double best_cost = 1e300;
      for (std::size_t i = 0; i < estimates.size(); ++i) {
        double cost = 0;
        for (const SE3& o : estimates)
          cost += (o.translation() - estimates[i].translation()).norm() +
                  rotationAngle((o.inverse() * estimates[i]).rotation());
        if (cost < best_cost) best_cost = cost, best = i;
      }
      anchorTrajectory(&t, estimates[best], SessionAnchor::kLoop);
      progress = changed = true;
    }
  }
  return changed;
}

}  // namespace server
}  // namespace hermes
