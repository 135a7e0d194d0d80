#include "hermes/server/map_consistency.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace hermes {
namespace server {
namespace {

KeyframeKey keyIn(const TrajectoryId& t, KeyframeId id) { return KeyframeKey{t.first, t.second, id}; }
TrajectoryId trajOf(const KeyframeKey& k) { return {k.agent, k.session}; }

/// World position of a stored landmark (nullopt without an anchor).
bool landmarkWorld(const GlobalMap& map, const TrajectoryId& tid, LandmarkId id, Vec3* p_W) {
  const TrajectoryMap* t = map.trajectory(tid.first, tid.second);
  if (!t || !t->anchored) return false;
  auto l = t->landmarks.find(id);
  if (l == t->landmarks.end() || l->second.anchor == kInvalidId) return false;
  auto k = t->keyframes.find(l->second.anchor);
  if (k == t->keyframes.end()) return false;
  *p_W = k->second.T_W_C * l->second.p_anchor;
  return true;
}

/// The landmark keypoint `kp` of keyframe `key` belongs to (kInvalidId if none).
LandmarkId landmarkOf(const GlobalMap& map, const KeyframeKey& key, std::uint32_t kp) {
  const StoredKeyframe* k = map.keyframe(key);
  if (!k || kp >= k->keyframe.keypoint_landmark.size()) return kInvalidId;
  return k->keyframe.keypoint_landmark[kp];
}

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

double rms(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x * x;
  return v.empty() ? 0 : std::sqrt(s / static_cast<double>(v.size()));
}

}  // namespace

TieConsistency measureLoopTies(const GlobalMap& map, double max_reproj_px) {
  TieConsistency out;
  std::vector<double> reproj, cross_reproj, dist, cross_dist;
  // Landmark of (from, kp_from) against keypoint kp_to of keyframe `to`.
  auto tie = [&](const KeyframeKey& from, std::uint32_t kp_from, const KeyframeKey& to, std::uint32_t kp_to) {
    const LandmarkId lid = landmarkOf(map, from, kp_from);
    Vec3 p_W;
    const StoredKeyframe* k = map.keyframe(to);
    const TrajectoryMap* tt = map.trajectory(to.agent, to.session);
    if (lid == kInvalidId || !k || !tt || !tt->anchored || !landmarkWorld(map, trajOf(from), lid, &p_W)) return;
    const Vec3 p_C = k->T_W_C.inverse() * p_W;
    if (p_C.z() <= 1e-6) return;
    const Keypoint& kp = k->keyframe.keypoints[kp_to];
    const double e = (k->camera.project(p_C) - Vec2(kp.u, kp.v)).norm();
    if (e > max_reproj_px) return;  // a wrong match or landmark, not the map's consistency
    const bool cross = from.agent != to.agent;
    reproj.push_back(e);
    if (cross) cross_reproj.push_back(e);
    if (kp.depth > 0) {
      const PinholeIntrinsics& c = k->camera;
      const Vec3 q_C(kp.depth * (kp.u - c.cx) / c.fx, kp.depth * (kp.v - c.cy) / c.fy, kp.depth);
      const double d = (p_C - q_C).norm();
      dist.push_back(d);
      if (cross) cross_dist.push_back(d);
    }
  };
  for (const LoopEdge& l : map.loops) {
    if (!l.accepted) continue;
    for (const LoopMatch& m : l.matches) {
      const KeyframeKey ka = keyIn(trajOf(l.a), m.kf_a), kb = keyIn(trajOf(l.b), m.kf_b);
      tie(ka, m.kp_a, kb, m.kp_b);
      tie(kb, m.kp_b, ka, m.kp_a);
    }
  }
  out.ties = static_cast<int>(reproj.size());
  out.cross_ties = static_cast<int>(cross_reproj.size());
  out.reproj_rms_px = rms(reproj);
  out.cross_reproj_rms_px = rms(cross_reproj);
  out.cross_reproj_median_px = median(cross_reproj);
  out.depth_ties = static_cast<int>(dist.size());
  out.cross_depth_ties = static_cast<int>(cross_dist.size());
  out.dist_rms_m = rms(dist);
  out.cross_dist_rms_m = rms(cross_dist);
  out.cross_dist_median_m = median(cross_dist);
  return out;
}

}  // namespace server
}  // namespace hermes
