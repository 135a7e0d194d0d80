#include "hermes/server/map_manager.h"

#include "hermes/server/pose_graph_io.h"
#include "map_manager_detail.h"

#include <algorithm>
#include <cmath>
#include <chrono>
#include <cstdlib>
#include <iterator>
#include <map>

namespace hermes {
namespace server {
using map_manager_detail::Clock;
using map_manager_detail::keyOf;
using map_manager_detail::msSince;

Status MapManagerParams::read(const Config& config, const std::string& prefix) {
  for (Status s : {place_recognition.read(config, prefix + "place_recognition."),
                   loop_closure.read(config, prefix + "loop_closure"),
                   pcm.read(config, prefix + "pcm"), pose_graph.read(config, prefix + "pose_graph")})
    if (!s) return s;
  const std::string p = prefix + "map.";
  struct IntKey { const char* name; int* v; };
  for (IntKey k : {IntKey{"ties_per_loop", &ties_per_loop}, IntKey{"rig_neighbours", &rig_neighbours},
                   IntKey{"max_candidates_per_keyframe", &max_candidates_per_keyframe},
                   IntKey{"spatial_candidates", &spatial_candidates},
                   IntKey{"optimize_every_submaps", &optimize_every_submaps},
                   IntKey{"min_world_loops", &min_world_loops},
                   IntKey{"loop_threads", &loop_threads},
                   IntKey{"duplicate_neighbours", &duplicate_neighbours},
                   IntKey{"duplicate_min_pair_loops", &duplicate_min_pair_loops},
                   IntKey{"closure_budget", &closure_budget},
                   IntKey{"closure_budget_swarm", &closure_budget_swarm},
                   IntKey{"closure_budget_min_robots", &closure_budget_min_robots},
                   IntKey{"timing_window", &timing_window},
                   IntKey{"deferred_closures", &deferred_closures},
                   IntKey{"sparse_pair_loops", &sparse_pair_loops}})
    if (config.has(p + k.name))
      if (Status s = config.get(p + k.name, k.v); !s) return s;
  for (auto [name, v] : {std::pair<const char*, double*>{"spatial_radius_m", &spatial_radius_m},
                         {"spatial_max_angle_deg", &spatial_max_angle_deg},
                         {"sparse_pair_sigma_m", &sparse_pair_sigma_m},
                         {"active_robot_s", &active_robot_s}})
    if (config.has(p + name))
      if (Status s = config.get(p + name, v); !s) return s;
  if (Status s = odometry.read(config); !s) return s;
  if (Status s = validate(); !s) return Error{p + ": " + s.error()};
  return Status::Ok();
}

void MapManagerParams::write(ConfigWriter& out, const std::string& prefix) const {
  place_recognition.write(out, prefix + "place_recognition.");
  loop_closure.write(&out, prefix + "loop_closure");
  pcm.write(&out, prefix + "pcm");
  pose_graph.write(&out, prefix + "pose_graph");
  const std::string p = prefix + "map.";
  out.set(p + "ties_per_loop", ties_per_loop);
  out.set(p + "rig_neighbours", rig_neighbours);
  out.set(p + "max_candidates_per_keyframe", max_candidates_per_keyframe);
  out.set(p + "optimize_every_submaps", optimize_every_submaps);
  out.set(p + "spatial_candidates", spatial_candidates);
  out.set(p + "spatial_radius_m", spatial_radius_m);
  out.set(p + "spatial_max_angle_deg", spatial_max_angle_deg);
  out.set(p + "min_world_loops", min_world_loops);
  out.set(p + "loop_threads", loop_threads);
  out.set(p + "duplicate_neighbours", duplicate_neighbours);
  out.set(p + "duplicate_min_pair_loops", duplicate_min_pair_loops);
  out.set(p + "closure_budget", closure_budget);
  out.set(p + "closure_budget_swarm", closure_budget_swarm);
  out.set(p + "closure_budget_min_robots", closure_budget_min_robots);
  out.set(p + "active_robot_s", active_robot_s);
  out.set(p + "timing_window", timing_window);
  out.set(p + "deferred_closures", deferred_closures);
  out.set(p + "sparse_pair_loops", sparse_pair_loops);
  out.set(p + "sparse_pair_sigma_m", sparse_pair_sigma_m);
}

Status MapManagerParams::validate() const {
  if (rig_neighbours < 1) return Error{"rig_neighbours must be >= 1"};
  if (max_candidates_per_keyframe < 0) return Error{"max_candidates_per_keyframe must be >= 0"};
  if (optimize_every_submaps < 0) return Error{"optimize_every_submaps must be >= 0"};
  if (spatial_candidates < 0) return Error{"spatial_candidates must be >= 0"};
  if (!(spatial_radius_m > 0)) return Error{"spatial_radius_m must be > 0"};
  if (!(spatial_max_angle_deg > 0 && spatial_max_angle_deg <= 180))
    return Error{"spatial_max_angle_deg must be in (0, 180]"};
  if (Status s = odometry.validate(); !s) return Error{"odometry: " + s.error()};
  if (ties_per_loop < 0) return Error{"ties_per_loop must be >= 0"};
  if (min_world_loops < 1) return Error{"min_world_loops must be >= 1"};
  if (loop_threads < 1 || loop_threads > 64) return Error{"loop_threads must be in 1..64"};
  if (duplicate_neighbours < 0) return Error{"duplicate_neighbours must be >= 0"};
  if (duplicate_min_pair_loops < 0) return Error{"duplicate_min_pair_loops must be >= 0"};
  if (closure_budget < 0) return Error{"closure_budget must be >= 0 (0 = verify all)"};
  if (closure_budget_swarm < 0) return Error{"closure_budget_swarm must be >= 0 (0 = off)"};
  if (closure_budget_min_robots < 1) return Error{"closure_budget_min_robots must be >= 1"};
  if (!(active_robot_s > 0) || !std::isfinite(active_robot_s)) return Error{"active_robot_s must be > 0"};
  if (timing_window < 0) return Error{"timing_window must be >= 0 (0 = keep all)"};
  if (deferred_closures < 0) return Error{"deferred_closures must be >= 0"};
  if (sparse_pair_loops < 0) return Error{"sparse_pair_loops must be >= 0 (0 = off)"};
  if (!(sparse_pair_sigma_m > 0) || !std::isfinite(sparse_pair_sigma_m))
    return Error{"sparse_pair_sigma_m must be > 0"};
  return Status::Ok();
}

namespace {

LoopClosureParams sparseGate(const MapManagerParams& p) {
  LoopClosureParams lc = p.loop_closure;
  lc.max_translation_sigma_m = std::max(lc.max_translation_sigma_m, p.sparse_pair_sigma_m);
  return lc;
}

}  // namespace

MapManager::MapManager(std::shared_ptr<const Vocabulary> vocabulary, MapManagerParams params,
                       Bookkeeper* bookkeeper)
    : vocabulary_(std::move(vocabulary)),
      params_(std::move(params)),
      bookkeeper_(bookkeeper),
      recognizer_(vocabulary_, params_.place_recognition),
      closer_(params_.loop_closure),
      sparse_closer_(sparseGate(params_)),
      timings_(static_cast<std::size_t>(params_.timing_window)),
      closure_budget_(params_.closure_budget) {}

Mat6 MapManager::bridgeInformation(const Keyframe& from, const Keyframe& to) const {
  return odometryInformation(from.T_A_C.inverse() * to.T_A_C, -1, to.lost_before, params_.odometry);
}

void MapManager::storeSubmap(RobotId robot, const Submap& submap,
                             std::vector<KeyframeKey>* added, std::vector<KeyframeKey>* extended,
                             MergeStats* stats) {
  const std::uint32_t session = submap.header.session;
  TrajectoryMap& t = map_.trajectories[{robot, session}];
  t.agent = robot;
  t.session = session;
  t.uuid = submap.header.agent;
  for (const OdometryEdge& e : submap.odometry) t.odometry[{e.from, e.to}] = e;
  std::vector<const Keyframe*> order;
  for (const Keyframe& kf : submap.keyframes) {
    if (submap.isExtension(kf)) {
      auto it = t.keyframes.find(kf.id);
      if (it == t.keyframes.end()) {
        ++stats->extensions_unknown;  // its window never arrived (or another session's)
        continue;
      }
      Keyframe& stored = it->second.keyframe;
      stored.keypoints.insert(stored.keypoints.end(), kf.keypoints.begin(), kf.keypoints.end());
      stored.descriptors.insert(stored.descriptors.end(), kf.descriptors.begin(), kf.descriptors.end());
      stored.keypoint_landmark.resize(stored.keypoints.size(), kInvalidId);
      extended->push_back(keyOf(t, kf.id));
      ++stats->keyframes_extended;
      continue;
    }
    if (!t.keyframes.count(kf.id)) order.push_back(&kf);
  }
  std::sort(order.begin(), order.end(),
            [](const Keyframe* a, const Keyframe* b) { return a->id < b->id; });
  for (const Keyframe* kf : order) {
    StoredKeyframe sk;
    sk.keyframe = *kf;
    sk.camera = submap.cameras[kf->camera_id];
    auto next = t.keyframes.lower_bound(kf->id);
    if (t.anchored) {
      // Follow the correction of the closest earlier keyframe (after optimisation).
      SE3 T_W_A = t.T_W_A;
      if (next != t.keyframes.begin()) {
        const StoredKeyframe& prev = std::prev(next)->second;
        T_W_A = prev.T_W_C * prev.keyframe.T_A_C.inverse();
      }
      sk.T_W_C = T_W_A * kf->T_A_C;
    }
    const bool last = next == t.keyframes.end();
    const KeyframeKey key = keyOf(t, kf->id);
    t.keyframes[kf->id] = std::move(sk);
    if (chain_.addKeyframe(key, kf->T_A_C) && last && t.keyframes.size() > 1) {
      const auto prev = std::prev(t.keyframes.find(kf->id));
      const KeyframeId prev_id = prev->first;
      auto e = t.odometry.find({prev_id, kf->id});
      const Mat6 info = e != t.odometry.end() ? e->second.information
                                              : bridgeInformation(prev->second.keyframe, *kf);
      (void)chain_.addEdge(keyOf(t, prev_id), key, info);
    }
    added->push_back(key);
    touched_.insert(key);
  }
  for (const Landmark& lm : submap.landmarks) {
    auto it = t.landmarks.find(lm.id);
    if (it == t.landmarks.end()) {
      StoredLandmark sl;
      sl.landmark = lm;
      GlobalMap::anchorLandmark(t, &sl);
      t.landmarks[lm.id] = std::move(sl);
    } else {
      auto& obs = it->second.landmark.observations;
      obs.insert(obs.end(), lm.observations.begin(), lm.observations.end());
      if (it->second.anchor == kInvalidId) GlobalMap::anchorLandmark(t, &it->second);
    }
  }
}

void MapManager::extendKeyframes(const std::vector<KeyframeKey>& extended, MergeStats* stats) {
  if (extended.empty()) return;
  const std::set<KeyframeKey> ext(extended.begin(), extended.end());
  for (const KeyframeKey& key : extended) {  // the database sees the new descriptors
    const StoredKeyframe* kf = map_.keyframe(key);
    recognizer_.remove(key);
    (void)recognizer_.addBow(key, kf->keyframe.stamp, recognizer_.bow(kf->keyframe.descriptors));
  }
  // Loops whose rig holds an extended keyframe are closed again with its keypoints.
  auto inRig = [&](const KeyframeKey& key) {
    if (ext.count(key)) return true;
    std::vector<PinholeIntrinsics> cams;
    for (const Keyframe* n : neighbours(key, &cams))
      if (ext.count(KeyframeKey{key.agent, key.session, n->id})) return true;
    return false;
  };
  std::vector<std::uint64_t> again;
  std::vector<std::pair<KeyframeKey, KeyframeKey>> pairs;
  for (const LoopEdge& loop : map_.loops)
    if (inRig(loop.a) || inRig(loop.b)) {
      again.push_back(loop.id);
      pairs.emplace_back(loop.a, loop.b);
    }
  if (closure_budget_ > 0) {  // under a budget: measured again while no submap waits
    std::set<std::uint64_t> waiting;
    for (const LoopJob& j : deferred_)
      if (j.reverify) waiting.insert(*j.reverify);
    for (std::size_t k = 0; k < again.size(); ++k) {
      if (waiting.count(again[k])) continue;
      PlaceCandidate c;
      c.key = pairs[k].second;
      defer(LoopJob{pairs[k].first, c, false, again[k]});
      ++stats->loops_reverify_deferred;
    }
    return;
  }
  const std::vector<LoopClosureResult> results = verifyPairs(pairs);
  for (std::size_t k = 0; k < again.size(); ++k) takeReverification(again[k], results[k], stats);
}

void MapManager::takeReverification(std::uint64_t loop_id, const LoopClosureResult& r,
                                    MergeStats* stats) {
  auto it = std::find_if(map_.loops.begin(), map_.loops.end(),
                         [&](const LoopEdge& e) { return e.id == loop_id; });
  if (it == map_.loops.end()) return;  // gone since it was deferred
  LoopEdge& loop = *it;
  ++stats->loops_reverified;
  std::optional<LoopEdge> e = loopEdge(loop.a, loop.b, r);
  if (!e || e->inliers < loop.inliers) return;  // keep the earlier measurement
  e->id = loop.id;
  e->accepted = loop.accepted;
  loop = *e;
  touched_.insert(loop.a);
  touched_.insert(loop.b);
  pcm_cache_.forget(loop.id);
  ++stats->loops_replaced;
}

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

Expected<PoseGraph> MapManager::buildPoseGraph() const {
  PoseGraph graph(params_.pose_graph);
  bool fixed = false;
  for (const auto& [tid, t] : map_.trajectories) {
    if (!t.anchored) continue;
    const StoredKeyframe* prev = nullptr;
    KeyframeId prev_id = kInvalidId;
    for (const auto& [id, kf] : t.keyframes) {
      const KeyframeKey key = keyOf(t, id);
      if (Status s = graph.addNode(key, kf.T_W_C); !s) return Error{s.error()};
      if (!fixed && world_traj_ && tid == *world_traj_) {
        if (Status s = graph.setFixed(key); !s) return Error{s.error()};
        fixed = true;
      }
      if (prev) {
        auto e = t.odometry.find({prev_id, id});
        const SE3 T = e != t.odometry.end() ? e->second.T_from_to
                                            : prev->keyframe.T_A_C.inverse() * kf.keyframe.T_A_C;
        const Mat6 info = e != t.odometry.end() ? e->second.information
                                                : bridgeInformation(prev->keyframe, kf.keyframe);
        if (Status s = graph.addOdometryEdge(keyOf(t, prev_id), key, T, info); !s) return Error{s.error()};
      }
      prev = &kf;
      prev_id = id;
    }
  }
  if (!fixed) return Error{"no anchored world trajectory yet"};
  for (const LoopEdge& e : map_.loops) {
    if (!e.accepted || !graph.hasNode(e.a) || !graph.hasNode(e.b)) continue;
    if (Status s = graph.addLoopEdge(e.a, e.b, e.T_a_b, e.information); !s) return Error{s.error()};
  }
  return graph;
}

Status MapManager::writePoseGraph(const std::string& path) const {
  Expected<PoseGraph> graph = buildPoseGraph();
  if (!graph) return Error{"pose graph for " + path + ": " + graph.error()};
  return writePoseGraphG2o(*graph, path);
}

Status MapManager::optimize(bool full) {
  const auto world = world_traj_ ? map_.trajectories.find(*world_traj_) : map_.trajectories.end();
  if (world == map_.trajectories.end() || world->second.keyframes.empty()) return Status::Ok();  // nothing anchored yet
  Expected<PoseGraph> built = buildPoseGraph();
  if (!built) return Error{"pose graph: " + built.error()};
  PoseGraph& graph = *built;
  const PoseGraphParams& pg = params_.pose_graph;
  // Between merges the full solve falls due (fullSolveDue()); a merge then only
  // solves incrementally.
  const bool incremental = !full && pg.incremental_hops > 0 && graph_diag_.solves > 0 &&
                           (pg.full_between_merges || incremental_since_full_ < pg.full_every);
  if (incremental && graph.holdBeyond(std::vector<KeyframeKey>(touched_.begin(), touched_.end()),
                                      pg.incremental_hops,
                                      static_cast<std::size_t>(pg.incremental_max_free)) == 0) {
    touched_.clear();  // nothing in the graph changed
    graph_dirty_ = false;
    merges_since_optimize_ = 0;
    return Status::Ok();
  }
  auto t0 = Clock::now();
  auto r = graph.optimize();
  const double ms = msSince(t0);
  if (!r) return Error{"pose graph: " + r.error()};
  noteSolve(graph, *r, incremental, ms);
  touched_.clear();
  for (auto& [tid, t] : map_.trajectories) {
    if (!t.anchored) continue;
    for (auto& [id, kf] : t.keyframes) {
      auto p = graph.pose(keyOf(t, id));
      if (p) kf.T_W_C = *p;
    }
  }
  graph_dirty_ = false;
  merges_since_optimize_ = 0;
  return Status::Ok();
}

void MapManager::noteSolve(const PoseGraph& graph, const PoseGraphResult& r, bool incremental, double ms) {
  timings_.add(incremental ? "pose_graph_incremental" : "pose_graph_full", ms);
  timings_.add("pose_graph", ms);
  graph_diag_.result = r;
  graph_diag_.edges = graph.residuals();
  ++graph_diag_.solves;
  if (!r.converged) ++graph_diag_.not_converged;
  graph_diag_.incremental += incremental;
  graph_diag_.last_incremental = incremental;
  graph_diag_.last_free_nodes = graph.numFree();
  graph_diag_.last_nodes = graph.numNodes();
  incremental_since_full_ = incremental ? incremental_since_full_ + 1 : 0;
}

bool MapManager::fullSolveDue() const {
  const PoseGraphParams& pg = params_.pose_graph;
  return pg.full_between_merges && pg.incremental_hops > 0 && graph_diag_.solves > 0 &&
         incremental_since_full_ >= pg.full_every;
}

Expected<FullSolve> MapManager::prepareFullSolve() const {
  Expected<PoseGraph> built = buildPoseGraph();
  if (!built) return Error{"full solve: " + built.error()};
  FullSolve job{std::move(*built), {}, std::nullopt, 0};
  job.snapshot = job.graph.poses();
  return job;
}

void FullSolve::run() {
  const auto t0 = std::chrono::steady_clock::now();
  try {  // on a thread of its own: an exception there would end the process
    result = graph.optimize();
  } catch (const std::exception& e) {
    result = Expected<PoseGraphResult>(Error{std::string("threw ") + e.what()});
  }
  ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

Status MapManager::applyFullSolve(const FullSolve& job) {
  if (!job.result) return Error{"full solve: not run"};
  if (!*job.result) return Error{"full solve: " + job.result->error()};
  noteSolve(job.graph, **job.result, /*incremental=*/false, job.ms);
  // Each keyframe the solve saw moves by its correction (solved * snapshot^-1,
  // the identity of the solve's frame when nothing merged meanwhile); one added
  // since moves with the last keyframe before it on its trajectory, and is
  // left to the next incremental solve (touched).
  for (auto& [tid, t] : map_.trajectories) {
    if (!t.anchored) continue;
    std::optional<SE3> correction;
    for (auto& [id, kf] : t.keyframes) {
      const KeyframeKey key = keyOf(t, id);
      auto before = job.snapshot.find(key);
      auto solved = job.graph.pose(key);
      if (before != job.snapshot.end() && solved) {
        correction = *solved * before->second.inverse();
        kf.T_W_C = before->second.matrix() == kf.T_W_C.matrix() ? *solved : *correction * kf.T_W_C;
      } else {
        if (correction) kf.T_W_C = *correction * kf.T_W_C;
        touched_.insert(key);
      }
    }
  }
  return Status::Ok();
}

Expected<MergeStats> MapManager::merge(RobotId robot, const Submap& submap,
                                       const std::function<double(RobotId)>& credibility) {
  const auto t_total = Clock::now();
  if (std::string v = submap.validate(); !v.empty())
    return Error{"merge of submap seq " + std::to_string(submap.header.seq) + " from " +
                 hermes::toString(submap.header.agent) + ": " + v};
  MergeStats stats;
  // A stage's wall time goes to the run's statistics and to this merge's breakdown.
  auto t0 = Clock::now();
  const auto stage = [&](const char* name) {
    const double ms = msSince(t0);
    timings_.add(name, ms);
    stats.stage_ms[name] += ms;
    t0 = Clock::now();
  };
  std::vector<KeyframeKey> added, extended;
  storeSubmap(robot, submap, &added, &extended, &stats);
  stage("store");
  stats.keyframes = static_cast<int>(added.size());
  stats.landmarks = static_cast<int>(submap.landmarks.size());
  const std::size_t loops_before = map_.loops.size();
  t0 = Clock::now();
  extendKeyframes(extended, &stats);
  stage("extend");
  detectLoops(added, &stats);
  stage("detect_loops");
  if (stats.loops_replaced > 0) graph_dirty_ = true;  // a loop's measurement changed
  if (map_.loops.size() != loops_before || stats.loops_replaced > 0) {
    runPcm();
    stage("pcm");
  }
  updateAnchoring(credibility);
  stage("anchoring");
  ++merges_since_optimize_;
  if (graph_dirty_ || (params_.optimize_every_submaps > 0 &&
                       merges_since_optimize_ >= params_.optimize_every_submaps)) {
    if (Status s = optimize(); !s) return Error{s.error()};
    stats.optimized = true;
    stage("optimize");
  }
  stats.stage_ms["total"] = msSince(t_total);
  timings_.add("merge_total", stats.stage_ms["total"]);
  return stats;
}

std::size_t MapManager::loopsAccepted() const { return accepted_.size(); }
std::size_t MapManager::loopsRejected() const { return map_.loops.size() - accepted_.size(); }

bool MapManager::hasLoops(RobotId robot) const {
  for (const LoopEdge& e : map_.loops)
    if (e.accepted && (e.a.agent == robot || e.b.agent == robot)) return true;
  return false;
}

int MapManager::agentsMerged() const {
  int n = 0;
  if (!bookkeeper_) return 0;
  for (RobotId r : bookkeeper_->robots())
    if (bookkeeper_->anchored(r)) ++n;
  return n;
}

}  // namespace server
}  // namespace hermes
