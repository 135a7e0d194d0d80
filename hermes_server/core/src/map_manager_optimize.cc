// MapManager, optimisation (map_manager.h): the pose graph of the anchored
// trajectories, incremental solves around what changed, full solves (also off
// the merging thread: FullSolve), the solves' diagnostics.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>

#include "hermes/server/map_manager.h"
#include "hermes/server/pose_graph_io.h"
#include "map_manager_detail.h"

namespace hermes {
namespace server {

using map_manager_detail::Clock;
using map_manager_detail::keyOf;
using map_manager_detail::msSince;

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

}  // namespace server
}  // namespace hermes
