// MapManager, loop detection (map_manager.h): the loop rigs, place and spatial
// candidates, near-duplicates, the closure budget and its deferred closures,
// verification side by side, loop edges.
#include <algorithm>
#include <iterator>
#include <map>

#include "hermes/core/parallel_jobs.h"
#include "hermes/server/closure_budget.h"
#include "hermes/server/map_manager.h"
#include "map_manager_detail.h"

namespace hermes {
namespace server {

using map_manager_detail::Clock;
using map_manager_detail::keyOf;
using map_manager_detail::msSince;

std::vector<const Keyframe*> MapManager::neighbours(const KeyframeKey& key,
                                                    std::vector<PinholeIntrinsics>* cams) const {
  std::vector<const Keyframe*> out;
  const TrajectoryMap* t = map_.trajectory(key.agent, key.session);
  if (!t) return out;
  auto self = t->keyframes.find(key.id);
  if (self == t->keyframes.end()) return out;
  cams->push_back(self->second.camera);
  // Earlier keyframes first, then later ones; never across a loss of tracking
  // (lost_before): the odometry that would place them is a relocalisation's.
  auto it = self;
  while (static_cast<int>(out.size()) < params_.rig_neighbours && it != t->keyframes.begin() &&
         !it->second.keyframe.lost_before) {
    --it;
    out.push_back(&it->second.keyframe);
    cams->push_back(it->second.camera);
  }
  it = std::next(self);
  while (static_cast<int>(out.size()) < params_.rig_neighbours && it != t->keyframes.end() &&
         !it->second.keyframe.lost_before) {
    out.push_back(&it->second.keyframe);
    cams->push_back(it->second.camera);
    ++it;
  }
  return out;
}

LoopClosureResult MapManager::verifyPair(const KeyframeKey& query, const KeyframeKey& candidate,
                                         bool sparse) const {
  LoopClosureResult r;
  const StoredKeyframe* q = map_.keyframe(query);
  const StoredKeyframe* c = map_.keyframe(candidate);
  if (!q || !c || query == candidate) {
    r.reason = "keyframe not stored or the query itself";
    return r;
  }
  std::vector<PinholeIntrinsics> qcams, ccams;
  const std::vector<const Keyframe*> qn = neighbours(query, &qcams);
  const std::vector<const Keyframe*> cn = neighbours(candidate, &ccams);
  return (sparse ? sparse_closer_ : closer_).close(q->keyframe, qn, qcams, c->keyframe, cn, ccams);
}

std::vector<LoopClosureResult> MapManager::verifyPairs(
    const std::vector<std::pair<KeyframeKey, KeyframeKey>>& pairs) {
  std::vector<LoopClosureResult> results(pairs.size());
  std::vector<double> ms(pairs.size(), 0.0);
  const auto t0 = Clock::now();
  // Sparse ties as the merge starts (the same for any loop_threads).
  std::vector<char> sparse(pairs.size(), 0);
  if (params_.sparse_pair_loops > 0 && !pairs.empty()) {
    const std::map<TrajectoryPair, int> accepted = acceptedLoopsPerPair(map_.loops);
    for (std::size_t i = 0; i < pairs.size(); ++i) {
      auto it = accepted.find(pairOf(pairs[i].first, pairs[i].second));
      sparse[i] = (it == accepted.end() ? 0 : it->second) < params_.sparse_pair_loops;
    }
  }
  runParallelJobs(pairs.size(), params_.loop_threads, [&](std::size_t i) {
    const auto t = Clock::now();
    results[i] = verifyPair(pairs[i].first, pairs[i].second, sparse[i]);
    ms[i] = msSince(t);
  });
  if (!pairs.empty()) timings_.add("loop_batch", msSince(t0));
  for (double m : ms) timings_.add("loop_closure", m);
  for (const LoopClosureResult& r : results) {  // where a closure's time goes
    if (r.time_ms <= 0) continue;
    timings_.add("loop_matching", r.time_ms - r.prefilter_ms - r.ransac_ms - r.refine_ms);
    timings_.add("loop_prefilter", r.prefilter_ms);
    timings_.add("loop_ransac", r.ransac_ms);
    timings_.add("loop_refine", r.refine_ms);
  }
  return results;
}

std::optional<LoopEdge> MapManager::loopEdge(const KeyframeKey& query, const KeyframeKey& candidate,
                                             const LoopClosureResult& r) const {
  if (!r.ok()) return std::nullopt;
  LoopEdge e;
  e.a = query;
  e.b = candidate;
  e.T_a_b = r.T_refQ_refC;
  if (loop_hook_) loop_hook_(e.a, e.b, &e.T_a_b);
  e.information = r.information;
  e.covariance = r.covariance;
  e.inliers = r.num_inliers;
  e.depth_inliers = r.num_depth_inliers;
  // Keep up to ties_per_loop inlier pairs (evenly spaced), rig cameras as keyframe ids.
  std::vector<PinholeIntrinsics> cams;
  std::vector<KeyframeId> rig_q{query.id}, rig_c{candidate.id};
  for (const Keyframe* k : neighbours(query, &cams)) rig_q.push_back(k->id);
  for (const Keyframe* k : neighbours(candidate, &cams)) rig_c.push_back(k->id);
  const std::size_t n = r.inlier_matches.size();
  const std::size_t keep = std::min<std::size_t>(n, static_cast<std::size_t>(params_.ties_per_loop));
  for (std::size_t j = 0; j < keep; ++j) {
    const RigMatch& m = r.inlier_matches[j * n / keep];
    if (m.cam_q < 0 || m.cam_c < 0 || m.cam_q >= static_cast<int>(rig_q.size()) ||
        m.cam_c >= static_cast<int>(rig_c.size()))
      continue;
    e.matches.push_back(LoopMatch{rig_q[m.cam_q], static_cast<std::uint32_t>(m.kp_q), rig_c[m.cam_c],
                                  static_cast<std::uint32_t>(m.kp_c)});
  }
  return e;
}

void MapManager::detectLoops(const std::vector<KeyframeKey>& added, MergeStats* stats) {
  // Candidates first (place recognition sees the keyframes in order; nothing
  // here depends on the loops found), then every closure side by side, then
  // the results in the candidates' order.
  std::vector<LoopJob> jobs;
  for (const KeyframeKey& key : added) {
    const StoredKeyframe* q = map_.keyframe(key);
    auto t0 = Clock::now();
    const BowVector bow = recognizer_.bow(q->keyframe.descriptors);
    PlaceQueryResult places = recognizer_.query(key, q->keyframe.stamp, bow);
    (void)recognizer_.addBow(key, q->keyframe.stamp, bow);
    timings_.add("place_recognition", msSince(t0));
    if (candidate_hook_) candidate_hook_(key, &places.candidates);
    stats->place_candidates += static_cast<int>(places.candidates.size());
    if (places.candidates.empty()) jobs.push_back(LoopJob{key, std::nullopt, false, std::nullopt});
    std::vector<KeyframeKey> tried;
    for (const PlaceCandidate& c : places.candidates) {
      if (static_cast<int>(tried.size()) >= params_.max_candidates_per_keyframe) break;
      if (!map_.keyframe(c.key) || c.key == key) continue;
      tried.push_back(c.key);
      jobs.push_back(LoopJob{key, c, false, std::nullopt});
    }
    for (const KeyframeKey& k : spatialCandidates(key, q->keyframe.stamp, tried)) {
      PlaceCandidate c;
      c.key = k;
      jobs.push_back(LoopJob{key, c, true, std::nullopt});
    }
  }
  // Near-duplicates wait for a second round: verified only when none of the
  // closures they duplicate gave a loop.
  const std::vector<std::vector<std::size_t>> dups = nearDuplicates(jobs);
  std::vector<LoopClosureResult> results(jobs.size());
  std::vector<char> skipped(jobs.size(), 0);
  // First-round loops per (query trajectory, candidate trajectory).
  using TrajPair = std::pair<std::pair<RobotId, std::uint32_t>, std::pair<RobotId, std::uint32_t>>;
  const auto trajPair = [](const LoopJob& j) {
    return TrajPair{{j.query.agent, j.query.session}, {j.candidate->key.agent, j.candidate->key.session}};
  };
  std::map<TrajPair, int> pair_loops;
  const std::vector<char> within = closuresWithinBudget(jobs, dups);
  int budget_left = closure_budget_;
  for (int round = 0; round < 2; ++round) {
    if (round == 1)
      for (std::size_t i = 0; i < jobs.size(); ++i)
        if (jobs[i].candidate && dups[i].empty() && results[i].ok()) ++pair_loops[trajPair(jobs[i])];
    std::vector<std::size_t> which;
    std::vector<std::pair<KeyframeKey, KeyframeKey>> pairs;
    for (std::size_t i = 0; i < jobs.size(); ++i) {
      if (!jobs[i].candidate || dups[i].empty() != (round == 0)) continue;
      if (!within[i] || (closure_budget_ > 0 && budget_left <= 0)) {
        skipped[i] = 2;
        continue;
      }
      if (round == 1 && pair_loops[trajPair(jobs[i])] >= params_.duplicate_min_pair_loops &&
          std::any_of(dups[i].begin(), dups[i].end(), [&](std::size_t d) { return results[d].ok(); })) {
        skipped[i] = 1;
        continue;
      }
      which.push_back(i);
      pairs.emplace_back(jobs[i].query, jobs[i].candidate->key);
      --budget_left;
    }
    std::vector<LoopClosureResult> verified = verifyPairs(pairs);
    for (std::size_t k = 0; k < which.size(); ++k) results[which[k]] = std::move(verified[k]);
  }
  for (std::size_t i = 0; i < jobs.size(); ++i) {
    const LoopJob& j = jobs[i];
    if (skipped[i] == 1) {
      ++stats->loops_skipped_duplicate;
      if (attempt_hook_)
        attempt_hook_(LoopAttempt{j.query, j.candidate, j.spatial, LoopStatus::kSkippedDuplicate,
                                  "near-duplicate of a loop found in this merge", 0, 0});
      continue;
    }
    if (skipped[i] == 2) {
      ++stats->loops_skipped_budget;
      defer(j);
      if (attempt_hook_)
        attempt_hook_(LoopAttempt{j.query, j.candidate, j.spatial, LoopStatus::kSkippedBudget,
                                  "over this merge's closure budget: deferred", 0, 0});
      continue;
    }
    takeClosure(j, results[i], stats);
  }
}

void MapManager::takeClosure(const LoopJob& j, const LoopClosureResult& r, MergeStats* stats) {
  if (!j.candidate) {
    if (attempt_hook_) attempt_hook_(LoopAttempt{j.query, std::nullopt, false, LoopStatus::kBadInput, "", 0, 0});
    return;
  }
  ++stats->loops_attempted;
  if (attempt_hook_)
    attempt_hook_(LoopAttempt{j.query, j.candidate, j.spatial, r.status, r.reason, r.num_matches,
                              r.num_inliers, r.num_prefiltered, r.ransac_iterations,
                              r.ransac_enough_at, r.time_ms, r.prefilter_ms, r.ransac_ms,
                              r.refine_ms});
  std::optional<LoopEdge> e = loopEdge(j.query, j.candidate->key, r);
  if (!e) return;
  ++stats->loops_geometric;
  e->id = next_loop_id_++;
  map_.loops.push_back(*e);
}

void MapManager::defer(const LoopJob& job) {
  if (params_.deferred_closures <= 0) {
    ++deferred_dropped_;
    return;
  }
  while (deferred_.size() >= static_cast<std::size_t>(params_.deferred_closures)) {
    deferred_.pop_front();  // the oldest: its place has had the longest to come again
    ++deferred_dropped_;
  }
  deferred_.push_back(job);
}

Expected<int> MapManager::closeDeferred(int max_closures, const std::function<double(RobotId)>& credibility,
                                        MergeStats* out) {
  if (deferred_.empty() || max_closures <= 0) return 0;
  const auto t_total = Clock::now();
  const std::map<TrajectoryPair, int> accepted = acceptedLoopsPerPair(map_.loops);
  std::vector<TrajectoryPair> pairs;
  for (const LoopJob& j : deferred_) pairs.push_back(pairOf(j.query, j.candidate->key));
  const std::vector<char> chosen = chooseWithinBudget(pairs, accepted, max_closures);
  std::vector<LoopJob> jobs;
  std::deque<LoopJob> rest;
  for (std::size_t i = 0; i < deferred_.size(); ++i) {
    const LoopJob& j = deferred_[i];
    if (!chosen[i]) rest.push_back(j);
    else if (map_.keyframe(j.query) && map_.keyframe(j.candidate->key)) jobs.push_back(j);
  }
  deferred_ = std::move(rest);
  std::vector<std::pair<KeyframeKey, KeyframeKey>> verify;
  for (const LoopJob& j : jobs) verify.emplace_back(j.query, j.candidate->key);
  const std::vector<LoopClosureResult> results = verifyPairs(verify);
  MergeStats local;
  MergeStats& stats = out ? *out : local;
  const std::size_t loops_before = map_.loops.size();
  for (std::size_t i = 0; i < jobs.size(); ++i) {
    if (jobs[i].reverify) takeReverification(*jobs[i].reverify, results[i], &stats);
    else takeClosure(jobs[i], results[i], &stats);
  }
  if (stats.loops_replaced > 0) graph_dirty_ = true;  // a loop's measurement changed
  if (map_.loops.size() != loops_before || stats.loops_replaced > 0) {
    auto t0 = Clock::now();
    runPcm();
    timings_.add("pcm", msSince(t0));
  }
  updateAnchoring(credibility);
  if (graph_dirty_ && deferred_.empty())  // the last slice; a merge solves on its own when dirty
    if (Status s = optimize(); !s) return Error{s.error()};
  timings_.add("deferred_closures", msSince(t_total));
  return static_cast<int>(jobs.size());
}

std::vector<char> MapManager::closuresWithinBudget(const std::vector<LoopJob>& jobs,
                                                   const std::vector<std::vector<std::size_t>>& dups) const {
  std::vector<char> within(jobs.size(), 1);
  if (closure_budget_ <= 0) return within;
  const std::map<TrajectoryPair, int> accepted = acceptedLoopsPerPair(map_.loops);
  // The first round is chosen; a near-duplicate follows the closures it duplicates.
  std::vector<std::size_t> first;
  std::vector<TrajectoryPair> pairs;
  for (std::size_t i = 0; i < jobs.size(); ++i) {
    if (!jobs[i].candidate || !dups[i].empty()) continue;
    first.push_back(i);
    pairs.push_back(pairOf(jobs[i].query, jobs[i].candidate->key));
  }
  const std::vector<char> chosen = chooseWithinBudget(pairs, accepted, closure_budget_);
  for (std::size_t k = 0; k < first.size(); ++k) within[first[k]] = chosen[k];
  for (std::size_t i = 0; i < jobs.size(); ++i)
    if (!dups[i].empty())
      within[i] = std::any_of(dups[i].begin(), dups[i].end(), [&](std::size_t d) { return within[d] != 0; });
  return within;
}

int MapManager::positionOf(const KeyframeKey& key) const {
  const TrajectoryMap* t = map_.trajectory(key.agent, key.session);
  if (!t) return -1;
  auto it = t->keyframes.find(key.id);
  return it == t->keyframes.end() ? -1 : static_cast<int>(std::distance(t->keyframes.begin(), it));
}

std::vector<std::vector<std::size_t>> MapManager::nearDuplicates(const std::vector<LoopJob>& jobs) const {
  std::vector<std::vector<std::size_t>> dups(jobs.size());
  const int n = params_.duplicate_neighbours;
  if (n <= 0) return dups;
  std::vector<int> qpos(jobs.size(), -1), cpos(jobs.size(), -1);
  for (std::size_t i = 0; i < jobs.size(); ++i)
    if (jobs[i].candidate) qpos[i] = positionOf(jobs[i].query), cpos[i] = positionOf(jobs[i].candidate->key);
  const auto sameTraj = [](const KeyframeKey& a, const KeyframeKey& b) {
    return a.agent == b.agent && a.session == b.session;
  };
  std::vector<std::size_t> first;  // first-round jobs so far
  for (std::size_t i = 0; i < jobs.size(); ++i) {
    if (!jobs[i].candidate || qpos[i] < 0 || cpos[i] < 0) continue;
    for (std::size_t f : first) {
      const LoopJob &a = jobs[f], &b = jobs[i];
      if (sameTraj(a.query, b.query) && sameTraj(a.candidate->key, b.candidate->key) &&
          std::abs(qpos[f] - qpos[i]) <= n && std::abs(cpos[f] - cpos[i]) <= n)
        dups[i].push_back(f);
    }
    if (dups[i].empty()) first.push_back(i);
  }
  return dups;
}

std::vector<KeyframeKey> MapManager::spatialCandidates(const KeyframeKey& key, double stamp,
                                                       const std::vector<KeyframeKey>& tried) const {
  std::vector<KeyframeKey> out;
  const TrajectoryMap* qt = map_.trajectory(key.agent, key.session);
  const StoredKeyframe* q = map_.keyframe(key);
  if (params_.spatial_candidates == 0 || !qt || !qt->anchored || !q) return out;
  const Vec3 c_q = q->T_W_C.translation();
  const Vec3 z_q = q->T_W_C.rotation().col(2);
  const double cos_max = std::cos(params_.spatial_max_angle_deg * M_PI / 180.0);
  // One candidate per place: none next to (within an island gap of) a place
  // candidate already tried or a keyframe already chosen.
  std::vector<KeyframeKey> taken = tried;
  const auto gap = static_cast<KeyframeId>(params_.place_recognition.island_id_gap);
  auto nextToTaken = [&](const KeyframeKey& k) {
    return std::any_of(taken.begin(), taken.end(), [&](const KeyframeKey& t) {
      return t.agent == k.agent && t.session == k.session && (t.id > k.id ? t.id - k.id : k.id - t.id) <= gap;
    });
  };
  std::vector<std::pair<double, KeyframeKey>> near;
  for (const auto& [tid, t] : map_.trajectories) {
    if (!t.anchored) continue;
    for (const auto& [id, kf] : t.keyframes) {
      const double d = (kf.T_W_C.translation() - c_q).norm();
      if (d > params_.spatial_radius_m || kf.T_W_C.rotation().col(2).dot(z_q) < cos_max) continue;
      const KeyframeKey k = keyOf(t, id);
      if (!recognizer_.excluded(key, stamp, k)) near.emplace_back(d, k);
    }
  }
  std::sort(near.begin(), near.end());
  for (const auto& [d, k] : near) {
    if (static_cast<int>(out.size()) >= params_.spatial_candidates) break;
    if (nextToTaken(k)) continue;
    out.push_back(k);
    taken.push_back(k);
  }
  return out;
}

}  // namespace server
}  // namespace hermes
