#include "hermes/server/group_bridge.h"

#include <deque>

#include "hermes/core/odometry_noise.h"

namespace hermes {
namespace server {

namespace {

using Trajectory = TieGroups::Trajectory;
Trajectory trajectoryOf(const KeyframeKey& k) { return {k.agent, k.session}; }

std::string trajectoryText(const Trajectory& t) {
  return "(agent " + std::to_string(t.first) + ", session " + std::to_string(t.second) + ")";
}

double translationVariance(const LoopCandidate& l) { return l.covariance.topLeftCorner<3, 3>().trace(); }

}  // namespace

TieGroups::TieGroups(OdometryQuery odometry) : odometry_(std::move(odometry)) {}

void TieGroups::tie(const LoopCandidate& loop) {
  const Trajectory ta = trajectoryOf(loop.a), tb = trajectoryOf(loop.b);
  if (ta == tb) return;
  // The best-measured tie per neighbour, oriented from the trajectory it is
  // stored under (ties by id: the same for any order).
  auto keep = [this](const Trajectory& from, const Trajectory& to, const LoopCandidate& l) {
    auto [it, fresh] = ties_[from].emplace(to, l);
    const double v = translationVariance(l), w = translationVariance(it->second);
    if (!fresh && (v < w || (v == w && l.id < it->second.id))) it->second = l;
  };
  keep(ta, tb, loop);
  keep(tb, ta, reversedLoop(loop));
  const Trajectory ra = group(ta), rb = group(tb);
  if (ra != rb) parent_[std::max(ra, rb)] = std::min(ra, rb);
}

Trajectory TieGroups::group(const Trajectory& t) const {
  Trajectory r = t;
  for (auto it = parent_.find(r); it != parent_.end() && it->second != r; it = parent_.find(r)) r = it->second;
  if (r != t) parent_[t] = r;  // path compression (one step)
  return r;
}

Expected<std::vector<LoopCandidate>> TieGroups::path(const Trajectory& from, const Trajectory& to) const {
  std::map<Trajectory, const LoopCandidate*> via;  // the tie that reached a trajectory
  std::deque<Trajectory> open{from};
  via[from] = nullptr;
  while (!open.empty() && !via.count(to)) {
    const Trajectory t = open.front();
    open.pop_front();
    auto it = ties_.find(t);
    if (it == ties_.end()) continue;
    for (const auto& [next, loop] : it->second)
      if (via.emplace(next, &loop).second) open.push_back(next);
  }
  if (!via.count(to))
    return Error{"no ties between trajectories " + trajectoryText(from) + " and " + trajectoryText(to)};
  std::vector<LoopCandidate> loops;
  for (Trajectory t = to; via.at(t); t = trajectoryOf(via.at(t)->a)) loops.push_back(*via.at(t));
  return std::vector<LoopCandidate>(loops.rbegin(), loops.rend());
}

Expected<RelativePose> TieGroups::relative(const KeyframeKey& from, const KeyframeKey& to) const {
  if (trajectoryOf(from) == trajectoryOf(to)) return odometry_(from, to);
  auto hops = path(trajectoryOf(from), trajectoryOf(to));
  if (!hops) return Error{hops.error()};
  // from -> (chain) -> tie.a -> (tie) -> tie.b -> (chain) -> ... -> to
  std::vector<RelativePoseCov> parts;
  double path_length = 0;
  KeyframeKey at = from;
  auto chain = [&](const KeyframeKey& until) -> Status {
    Expected<RelativePose> o = odometry_(at, until);
    if (!o) return Error{o.error()};
    parts.push_back({o->T, o->covariance});
    path_length += o->path_length_m;
    return Status::Ok();
  };
  for (const LoopCandidate& l : *hops) {
    if (Status s = chain(l.a); !s) return Error{s.error()};
    parts.push_back({l.T_a_b, l.covariance});
    path_length += l.T_a_b.translation().norm();
    at = l.b;
  }
  if (Status s = chain(to); !s) return Error{s.error()};
  const RelativePoseCov c = composeEdges(parts);
  RelativePose out;
  out.T = c.T;
  out.covariance = c.covariance;
  out.path_length_m = path_length;
  return out;
}

OdometryQuery TieGroups::query() const {
  return [this](const KeyframeKey& from, const KeyframeKey& to) { return relative(from, to); };
}

BridgeResult bridgeTieGroups(const std::vector<LoopCandidate>& loops,
                             const std::set<std::uint64_t>& accepted,
                             const OdometryQuery& odometry, const PcmParams& params) {
  BridgeResult res;
  if (params.bridge_min_loops <= 0) return res;
  TieGroups groups(odometry);
  for (const LoopCandidate& l : loops)
    if (accepted.count(l.id)) groups.tie(l);
  std::set<std::uint64_t> taken;
  const double gate = chi2Quantile(params.chi2_probability, 6);
  for (bool joined = true; joined;) {
    joined = false;
    // Loops between two different groups, oriented from the smaller group.
    std::map<std::pair<Trajectory, Trajectory>, std::vector<LoopCandidate>> between;
    for (const LoopCandidate& l : loops) {
      if (accepted.count(l.id) || taken.count(l.id)) continue;
      const Trajectory ga = groups.group(trajectoryOf(l.a)), gb = groups.group(trajectoryOf(l.b));
      if (ga == gb) continue;
      between[{std::min(ga, gb), std::max(ga, gb)}].push_back(gb < ga ? reversedLoop(l) : l);
    }
    std::vector<LoopCandidate> best;
    for (const auto& [pair, group] : between) {
      const int n = static_cast<int>(group.size());
      if (n < params.bridge_min_loops) continue;
      std::vector<std::vector<char>> adj(n, std::vector<char>(n, 0));
      for (int i = 0; i < n; ++i)
        for (int j = i + 1; j < n; ++j) {
          ++res.pairs_computed;
          Expected<double> d2 = cycleMahalanobis2(group[i], group[j], groups.query(), params);
          if (!d2) {
            ++res.odometry_failures;
            continue;
          }
          adj[i][j] = adj[j][i] = *d2 < gate;
        }
      bool exact = true;
      const std::vector<int> clique = maximumClique(adj, params.exact_max_loops, &exact);
      std::set<std::pair<Trajectory, Trajectory>> pairs;
      for (int v : clique) pairs.insert({trajectoryOf(group[v].a), trajectoryOf(group[v].b)});
      if (static_cast<int>(clique.size()) < params.bridge_min_loops || pairs.size() < 2) continue;
      if (clique.size() <= best.size()) continue;  // the largest bridge first
      best.clear();
      for (int v : clique) best.push_back(group[v]);
    }
    if (best.empty()) break;
    for (const LoopCandidate& l : best) {
      groups.tie(l);
      taken.insert(l.id);
      res.accepted.push_back(l.id);
    }
    ++res.bridges;
    joined = true;
  }
  return res;
}

LoopCandidate loopCandidate(const LoopEdge& e) {
  LoopCandidate c;
  c.id = e.id;
  c.a = e.a;
  c.b = e.b;
  c.T_a_b = e.T_a_b;
  c.covariance = e.covariance;
  return c;
}

std::vector<SE3> groupAnchorEstimates(const GlobalMap& map, const TieGroups& groups,
                                      const TrajectoryMap& t) {
  std::vector<SE3> estimates;
  if (t.anchored || t.keyframes.empty()) return estimates;
  const Trajectory mine{t.agent, t.session};
  const KeyframeKey k{t.agent, t.session, t.keyframes.begin()->first};
  const SE3& T_A_Ck = t.keyframes.begin()->second.keyframe.T_A_C;
  for (const LoopEdge& e : map.loops) {
    if (!e.accepted) continue;
    const TrajectoryMap* ta = map.trajectory(e.a.agent, e.a.session);
    const TrajectoryMap* tb = map.trajectory(e.b.agent, e.b.session);
    if (!ta || !tb || ta->anchored == tb->anchored) continue;
    const bool a_member = !ta->anchored;
    const KeyframeKey& m = a_member ? e.a : e.b;
    const StoredKeyframe* other = map.keyframe(a_member ? e.b : e.a);
    if (!other || trajectoryOf(m) == mine || groups.group(trajectoryOf(m)) != groups.group(mine)) continue;
    const Expected<RelativePose> m_to_k = groups.relative(m, k);  // T_Cm_Ck
    if (!m_to_k) continue;
    const SE3 T_W_Cm = a_member ? other->T_W_C * e.T_a_b.inverse() : other->T_W_C * e.T_a_b;
    estimates.push_back(T_W_Cm * m_to_k->T * T_A_Ck.inverse());
  }
  return estimates;
}

}  // namespace server
}  // namespace hermes
