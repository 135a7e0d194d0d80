// Submap surgery: restrict to kept keyframes (plus odometry edges) and to kept
// landmarks (keypoints re-indexed).
#include <algorithm>
#include <unordered_map>
#include <unordered_set>

#include "hermes/core/odometry_noise.h"
#include "hermes/distill/keyframe_trimming.h"

namespace hermes {
namespace distill {

int sharedLandmarks(const Submap& w, std::size_t a, std::size_t b) {
  if (a >= w.keyframes.size() || b >= w.keyframes.size()) return 0;
  const KeyframeId ia = w.keyframes[a].id, ib = w.keyframes[b].id;
  int shared = 0;
  for (const Landmark& lm : w.landmarks) {
    bool sa = false, sb = false;
    for (const Observation& ob : lm.observations) {
      sa = sa || ob.keyframe == ia;
      sb = sb || ob.keyframe == ib;
    }
    shared += (sa && sb) ? 1 : 0;
  }
  return shared;
}

Submap applyKeyframeTrim(const Submap& w, const std::vector<int>& kept) {
  Submap out;
  out.header = w.header;
  out.cameras = w.cameras;
  std::unordered_set<KeyframeId> kept_ids;
  for (int j : kept) {
    out.keyframes.push_back(w.keyframes[static_cast<std::size_t>(j)]);
    kept_ids.insert(w.keyframes[static_cast<std::size_t>(j)].id);
  }
  std::unordered_set<LandmarkId> kept_lms;
  for (const Landmark& lm : w.landmarks) {
    Landmark l = lm;
    l.observations.clear();
    for (const Observation& ob : lm.observations)
      if (kept_ids.count(ob.keyframe)) l.observations.push_back(ob);
    if (l.observations.empty()) continue;
    kept_lms.insert(l.id);
    out.landmarks.push_back(std::move(l));
  }
  for (Keyframe& kf : out.keyframes)
    for (LandmarkId& id : kf.keypoint_landmark)
      if (id != kInvalidId && !kept_lms.count(id)) id = kInvalidId;
  // The window's edges by their first keyframe; kept keyframes in window order.
  std::unordered_map<KeyframeId, const OdometryEdge*> edge_from;
  for (const OdometryEdge& e : w.odometry) edge_from[e.from] = &e;
  std::vector<int> order = kept;
  std::sort(order.begin(), order.end());
  // A loss of tracking before a dropped keyframe is a loss before the next kept
  // one (the server then knows not to trust its bridge across the gap).
  std::unordered_map<KeyframeId, bool> lost;
  for (std::size_t k = 0; k < order.size(); ++k) {
    bool any = false;
    for (int j = k == 0 ? 0 : order[k - 1] + 1; j <= order[k]; ++j)
      any = any || w.keyframes[static_cast<std::size_t>(j)].lost_before;
    lost[w.keyframes[static_cast<std::size_t>(order[k])].id] = any;
  }
  for (Keyframe& kf : out.keyframes) kf.lost_before = lost.at(kf.id);
  for (std::size_t k = 1; k < order.size(); ++k) {
    std::vector<RelativePoseCov> chain;
    bool complete = true;
    for (int j = order[k - 1]; j < order[k] && complete; ++j) {
      auto it = edge_from.find(w.keyframes[static_cast<std::size_t>(j)].id);
      complete = it != edge_from.end() && it->second->to == w.keyframes[static_cast<std::size_t>(j) + 1].id;
      if (!complete) break;
      auto cov = invertSpd(it->second->information);
      complete = cov.ok();
      if (complete) chain.push_back({it->second->T_from_to, *cov});
    }
    if (!complete) continue;  // the server bridges the gap from the poses
    const RelativePoseCov c = composeEdges(chain);
    auto info = invertSpd(c.covariance);
    if (!info.ok()) continue;
    OdometryEdge e;
    e.from = w.keyframes[static_cast<std::size_t>(order[k - 1])].id;
    e.to = w.keyframes[static_cast<std::size_t>(order[k])].id;
    e.T_from_to = c.T;
    e.information = *info;
    out.odometry.push_back(e);
  }
  return out;
}

namespace {

/// Marks up to `n` of a keyframe's keypoints not linked to a kept landmark, spread
/// evenly over their order (which follows the image grid), those with a measured
/// depth first: loop closure uses both their bearing and their depth.
std::vector<bool> extraKeypoints(const Keyframe& kf, const std::unordered_set<LandmarkId>& keep,
                                 std::size_t n) {
  std::vector<bool> take(kf.keypoints.size(), false);
  std::vector<std::size_t> with_depth, without;
  for (std::size_t p = 0; p < kf.keypoints.size(); ++p) {
    const LandmarkId id = kf.keypoint_landmark[p];
    if (id != kInvalidId && keep.count(id)) continue;
    (kf.keypoints[p].depth > 0 ? with_depth : without).push_back(p);
  }
  for (const std::vector<std::size_t>* group : {&with_depth, &without}) {
    const std::size_t m = std::min(n, group->size());
    for (std::size_t j = 0; j < m; ++j) take[(*group)[j * group->size() / m]] = true;
    n -= m;
  }
  return take;
}

}  // namespace

Submap keepLandmarks(const Submap& s, const std::vector<int>& landmark_indices,
                     std::size_t extra_keypoints) {
  Submap out;
  out.header = s.header;
  out.cameras = s.cameras;
  out.odometry = s.odometry;
  std::unordered_set<LandmarkId> keep;
  for (int i : landmark_indices) keep.insert(s.landmarks[static_cast<std::size_t>(i)].id);
  // Old keypoint index -> new, per keyframe.
  std::unordered_map<KeyframeId, std::vector<std::uint32_t>> remap;
  for (const Keyframe& kf : s.keyframes) {
    Keyframe k = kf;
    k.keypoints.clear();
    k.descriptors.clear();
    k.keypoint_landmark.clear();
    std::vector<std::uint32_t>& map = remap[kf.id];
    map.assign(kf.keypoints.size(), ~std::uint32_t{0});
    // Every selection round comes here without extras: no per-keyframe mask then.
    const std::vector<bool> extra =
        extra_keypoints > 0 ? extraKeypoints(kf, keep, extra_keypoints) : std::vector<bool>();
    for (std::size_t p = 0; p < kf.keypoints.size(); ++p) {
      const LandmarkId id = kf.keypoint_landmark[p];
      const bool linked = id != kInvalidId && keep.count(id);
      if (!linked && (extra.empty() || !extra[p])) continue;
      map[p] = static_cast<std::uint32_t>(k.keypoints.size());
      k.keypoints.push_back(kf.keypoints[p]);
      k.descriptors.push_back(kf.descriptors[p]);
      k.keypoint_landmark.push_back(linked ? id : kInvalidId);
    }
    out.keyframes.push_back(std::move(k));
  }
  std::vector<int> sorted = landmark_indices;
  std::sort(sorted.begin(), sorted.end());
  for (int i : sorted) {
    Landmark l = s.landmarks[static_cast<std::size_t>(i)];
    std::vector<Observation> obs;
    for (const Observation& ob : l.observations) {
      auto it = remap.find(ob.keyframe);
      if (it == remap.end() || ob.keypoint >= it->second.size()) continue;
      const std::uint32_t np = it->second[ob.keypoint];
      if (np == ~std::uint32_t{0}) continue;
      obs.push_back({ob.keyframe, np});
    }
    l.observations = std::move(obs);
    out.landmarks.push_back(std::move(l));
  }
  return out;
}

namespace {

/// The keyframe with only the keypoints `take` marks, none linked to a landmark.
Keyframe unlinkedSubset(const Keyframe& kf, const std::vector<bool>& take) {
  Keyframe k = kf;
  k.keypoints.clear();
  k.descriptors.clear();
  k.keypoint_landmark.clear();
  for (std::size_t p = 0; p < kf.keypoints.size(); ++p) {
    if (!take[p]) continue;
    k.keypoints.push_back(kf.keypoints[p]);
    k.descriptors.push_back(kf.descriptors[p]);
    k.keypoint_landmark.push_back(kInvalidId);
  }
  return k;
}

}  // namespace

Submap heldBackKeypoints(const Submap& s, const std::vector<int>& landmark_indices) {
  Submap out;
  out.header = s.header;
  out.cameras = s.cameras;
  std::unordered_set<LandmarkId> keep;
  for (int i : landmark_indices) keep.insert(s.landmarks[static_cast<std::size_t>(i)].id);
  for (const Keyframe& kf : s.keyframes) {
    std::vector<bool> take(kf.keypoints.size());
    for (std::size_t p = 0; p < kf.keypoints.size(); ++p)
      take[p] = kf.keypoint_landmark[p] == kInvalidId || !keep.count(kf.keypoint_landmark[p]);
    out.keyframes.push_back(unlinkedSubset(kf, take));
  }
  return out;
}

std::vector<Keyframe> keyframeExtensions(const Submap& held, std::size_t n) {
  std::vector<Keyframe> out;
  const std::unordered_set<LandmarkId> none;
  for (const Keyframe& kf : held.keyframes) {
    Keyframe k = unlinkedSubset(kf, extraKeypoints(kf, none, n));
    if (!k.keypoints.empty()) out.push_back(std::move(k));
  }
  return out;
}

}  // namespace distill
}  // namespace hermes
