// MapManager, storing (map_manager.h): a submap's keyframes and landmarks under
// (agent, session, id), the odometry chain, keyframe extensions and the loops
// they make worth closing again.
#include <algorithm>
#include <iterator>
#include <map>

#include "hermes/server/map_manager.h"
#include "map_manager_detail.h"

namespace hermes {
namespace server {

using map_manager_detail::Clock;
using map_manager_detail::keyOf;
using map_manager_detail::msSince;

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

}  // namespace server
}  // namespace hermes
