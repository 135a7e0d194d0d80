// MapManager checkpoint: everything a merge depends on, so that a manager
// loaded from it merges the next submap exactly as the saved one would have.
#include "hermes/server/byte_codec.h"
#include "hermes/server/map_manager.h"

namespace hermes {
namespace server {

void MapManager::save(ByteWriter* w) const {
  w->blob(map_.toBytes());
  chain_.save(w);
  const std::vector<KeyframeKey> places = recognizer_.database().keysInSlotOrder();
  w->count(places.size());
  for (const KeyframeKey& k : places) w->key(k);
  w->pod(next_loop_id_);
  w->pod(static_cast<std::int32_t>(merges_since_optimize_));
  w->flag(graph_dirty_);
  w->flag(world_traj_.has_value());
  w->pod(world_traj_ ? world_traj_->first : 0u);
  w->pod(world_traj_ ? world_traj_->second : 0u);
  w->pod(static_cast<std::int32_t>(graph_diag_.solves));
  w->pod(static_cast<std::int32_t>(graph_diag_.not_converged));
  saveTimings(w, timings_);
  // The closures a budget deferred: a restarted server still verifies them.
  w->count(deferred_.size());
  for (const LoopJob& j : deferred_) {
    w->key(j.query);
    const PlaceCandidate& c = *j.candidate;  // a deferred closure always has one
    w->key(c.key);
    w->pod(c.score);
    w->pod(c.normalized_score);
    w->pod(c.island_score);
    w->pod(c.island_first);
    w->pod(c.island_last);
    w->pod(static_cast<std::int32_t>(c.island_size));
    w->flag(j.spatial);
    w->flag(j.reverify.has_value());
    w->pod(j.reverify.value_or(0));
  }
  w->pod(static_cast<std::uint64_t>(deferred_dropped_));
}

Status MapManager::load(ByteReader* r) {
  if (!map_.trajectories.empty() || recognizer_.database().size() > 0)
    return Error{"map manager: load into a manager that already holds a map"};
  std::vector<std::uint8_t> map_bytes;
  if (!r->blob(&map_bytes)) return Error{"map manager: global map block truncated"};
  Expected<GlobalMap> map = GlobalMap::fromBytes(map_bytes, "block");
  if (!map) return Error{"map manager: " + map.error()};
  map_ = std::move(*map);
  if (!chain_.load(r)) return Error{"map manager: odometry chain damaged"};
  std::uint64_t n = 0;
  if (!r->count(&n, 16)) return Error{"map manager: bad place database count"};
  for (std::uint64_t i = 0; i < n; ++i) {
    KeyframeKey k;
    if (!r->key(&k)) return Error{"map manager: place database truncated"};
    const StoredKeyframe* kf = map_.keyframe(k);
    if (!kf || recognizer_.database().contains(k))
      return Error{"map manager: place database entry " + std::to_string(i) +
                   " names a keyframe the map does not hold (or twice)"};
    if (Status s = recognizer_.add(k, kf->keyframe.stamp, kf->keyframe.descriptors); !s)
      return Error{"map manager: place database: " + s.error()};
  }
  std::int32_t merges = 0, solves = 0, not_converged = 0;
  bool has_world = false;
  TrajectoryId world;
  if (!r->pod(&next_loop_id_) || !r->pod(&merges) || merges < 0 || !r->flag(&graph_dirty_) ||
      !r->flag(&has_world) || !r->pod(&world.first) || !r->pod(&world.second) ||
      !r->pod(&solves) || !r->pod(&not_converged) || solves < 0 || not_converged < 0)
    return Error{"map manager: counters damaged"};
  if (has_world && !map_.trajectories.count(world))
    return Error{"map manager: the world trajectory is not in the map"};
  if (!loadTimings(r, &timings_)) return Error{"map manager: timings damaged"};
  // Deferred closures may name keyframes gone since (they are skipped when verified).
  if (!r->count(&n, 3 * sizeof(KeyframeKey)))
    return Error{"map manager: bad deferred closure count"};
  for (std::uint64_t i = 0; i < n; ++i) {
    LoopJob j;
    PlaceCandidate c;
    std::int32_t island = 0;
    bool reverify = false;
    std::uint64_t loop_id = 0;
    if (!r->key(&j.query) || !r->key(&c.key) || !r->pod(&c.score) || !r->pod(&c.normalized_score) ||
        !r->pod(&c.island_score) || !r->pod(&c.island_first) || !r->pod(&c.island_last) ||
        !r->pod(&island) || !r->flag(&j.spatial) || !r->flag(&reverify) || !r->pod(&loop_id))
      return Error{"map manager: deferred closure " + std::to_string(i) + " truncated"};
    c.island_size = island;
    if (reverify) j.reverify = loop_id;
    j.candidate = c;
    deferred_.push_back(j);
  }
  std::uint64_t dropped = 0;
  if (!r->pod(&dropped)) return Error{"map manager: deferred closure counters damaged"};
  deferred_dropped_ = dropped;
  for (const LoopEdge& e : map_.loops) {
    if (e.id >= next_loop_id_) return Error{"map manager: loop id beyond the next id"};
    if (e.accepted) accepted_.insert(e.id);
  }
  merges_since_optimize_ = merges;
  graph_diag_.solves = solves;
  graph_diag_.not_converged = not_converged;
  if (has_world) world_traj_ = world;
  pcm_cache_.clear();
  pcm_chain_revision_ = chain_.revision();
  return Status::Ok();
}

void MapManager::renameAgents(const std::map<Uuid, Uuid>& renamed) {
  for (auto& [id, t] : map_.trajectories)
    if (auto it = renamed.find(t.uuid); it != renamed.end()) t.uuid = it->second;
}

}  // namespace server
}  // namespace hermes
