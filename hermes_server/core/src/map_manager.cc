// MapManager: its parameters and the merge pipeline, one stage after the other
// (merge(): store -> extend -> detect_loops -> pcm -> anchoring -> optimize).
// The stages live beside it: map_manager_store.cc, map_manager_loops.cc,
// map_manager_anchoring.cc, map_manager_optimize.cc; persistence in
// map_manager_io.cc.
#include "hermes/server/map_manager.h"

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
    if (bookkeeper_->anchored(r) && !bookkeeper_->isPrior(r)) ++n;
  return n;
}

int MapManager::priorAgents() const {
  int n = 0;
  if (!bookkeeper_) return 0;
  for (RobotId r : bookkeeper_->robots())
    if (bookkeeper_->isPrior(r)) ++n;
  return n;
}

}  // namespace server
}  // namespace hermes
