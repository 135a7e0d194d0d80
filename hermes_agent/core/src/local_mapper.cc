#include "hermes/agent/local_mapper.h"

#include <algorithm>
#include <unordered_map>

#include "hermes/agent/covisibility.h"

namespace hermes {

Status LocalMapperParams::read(const Config& c) {
  Status s = c.get("mapping.enable_ba", &enable_ba);
  if (!s) return s;
  for (auto [key, ptr] : {std::pair<const char*, int*>{"ba_window", &ba_window},
                          {"max_fixed", &max_fixed},
                          {"min_shared", &min_shared},
                          {"cull_after_keyframes", &cull_after_keyframes},
                          {"min_observations", &min_observations}}) {
    s = c.get(std::string("mapping.") + key, ptr);
    if (!s) return s;
  }
  for (auto [key, ptr] : {std::pair<const char*, double*>{"min_found_ratio", &min_found_ratio},
                          {"virtual_baseline", &virtual_baseline}}) {
    s = c.get(std::string("mapping.") + key, ptr);
    if (!s) return s;
  }
  s = ba.read(c, "mapping.ba");
  if (!s) return s;
  return validate();
}

void LocalMapperParams::write(ConfigWriter* w) const {
  w->set("mapping.enable_ba", enable_ba);
  w->set("mapping.ba_window", ba_window);
  w->set("mapping.max_fixed", max_fixed);
  w->set("mapping.min_shared", min_shared);
  w->set("mapping.cull_after_keyframes", cull_after_keyframes);
  w->set("mapping.min_observations", min_observations);
  w->set("mapping.min_found_ratio", min_found_ratio);
  w->set("mapping.virtual_baseline", virtual_baseline);
  ba.write(w, "mapping.ba");
}

Status LocalMapperParams::validate() const {
  if (ba_window < 1) return Error{"mapping.ba_window must be >= 1"};
  if (max_fixed < 0) return Error{"mapping.max_fixed must be >= 0"};
  if (min_shared < 1) return Error{"mapping.min_shared must be >= 1"};
  if (cull_after_keyframes < 1) return Error{"mapping.cull_after_keyframes must be >= 1"};
  if (min_observations < 1) return Error{"mapping.min_observations must be >= 1"};
  if (!(min_found_ratio >= 0 && min_found_ratio <= 1))
    return Error{"mapping.min_found_ratio must be in [0, 1]"};
  if (!(virtual_baseline > 0)) return Error{"mapping.virtual_baseline must be > 0"};
  return ba.validate();
}

LocalMapper::LocalMapper(const LocalMapperParams& params, const PinholeIntrinsics& K,
                         double baseline)
    : params_(params), K_(K), baseline_(baseline > 0 ? baseline : params.virtual_baseline) {}

void LocalMapper::noteCreated(LandmarkId id, KeyframeId keyframe) {
  if (id >= origin_.size()) {
    origin_.resize(id + 1, 0);
    visible_.resize(id + 1, 0);
    found_.resize(id + 1, 0);
    bad_.resize(id + 1, false);
  }
  origin_[id] = keyframe;
}

void LocalMapper::noteVisible(LandmarkId id, bool found) {
  if (id >= visible_.size()) return;
  ++visible_[id];
  found_[id] += found;
}

void LocalMapper::removeObservation(std::vector<Keyframe>* kfs, Landmark* l, std::size_t index) {
  const Observation o = l->observations[index];
  if (o.keyframe < kfs->size() && o.keypoint < (*kfs)[o.keyframe].keypoint_landmark.size())
    (*kfs)[o.keyframe].keypoint_landmark[o.keypoint] = kInvalidId;
  l->observations.erase(l->observations.begin() + index);
}

void LocalMapper::cull(std::vector<Keyframe>* kfs, Landmark* l) {
  while (!l->observations.empty()) removeObservation(kfs, l, l->observations.size() - 1);
  if (l->id < bad_.size()) bad_[l->id] = true;
}

LocalMappingStats LocalMapper::process(std::vector<Keyframe>* kfs, std::vector<Landmark>* lms,
                                       const std::vector<float>& scales) {
  LocalMappingStats st;
  if (kfs->empty()) return st;
  const KeyframeId newest = kfs->back().id;

  // 1. Culling of young landmarks that did not prove themselves.
  for (LandmarkId id = 0; id < lms->size() && id < origin_.size(); ++id) {
    if (bad_[id]) continue;
    const KeyframeId age = newest - origin_[id];
    if (age != KeyframeId(params_.cull_after_keyframes)) continue;  // checked once
    Landmark& l = (*lms)[id];
    const bool few = int(l.observations.size()) < params_.min_observations;
    const bool rarely = visible_[id] >= 5 && found_[id] < params_.min_found_ratio * visible_[id];
    if (few || rarely) {
      cull(kfs, &l);
      ++st.culled;
    }
  }
  if (!params_.enable_ba || kfs->size() < 2) return st;

  // 2. Window: newest ba_window keyframes free, covisible older ones fixed.
  const std::size_t first_free =
      kfs->size() > std::size_t(params_.ba_window) ? kfs->size() - params_.ba_window : 0;
  std::unordered_map<KeyframeId, int> pose_index;
  BaProblem pb;
  pb.K = K_;
  pb.baseline = baseline_;
  std::vector<KeyframeId> pose_kf;
  auto addPose = [&](KeyframeId k, bool fixed) {
    if (pose_index.count(k)) return;
    pose_index[k] = int(pb.T_C_W.size());
    pb.T_C_W.push_back((*kfs)[k].T_A_C.inverse());
    pb.pose_fixed.push_back(fixed);
    pose_kf.push_back(k);
  };
  for (std::size_t k = first_free; k < kfs->size(); ++k) addPose(k, k == 0);
  std::unordered_map<KeyframeId, int> fixed_votes;
  for (std::size_t k = first_free; k < kfs->size(); ++k)
    for (const auto& [other, n] : covisibleKeyframes(*kfs, *lms, k, params_.min_shared))
      if (other < first_free) fixed_votes[other] += n;
  std::vector<std::pair<int, KeyframeId>> fixed;
  for (const auto& [k, n] : fixed_votes) fixed.emplace_back(n, k);
  std::sort(fixed.rbegin(), fixed.rend());
  if (int(fixed.size()) > params_.max_fixed) fixed.resize(params_.max_fixed);
  for (const auto& f : fixed) addPose(f.second, true);
  if (fixed.empty() && first_free > 0) addPose(first_free - 1, true);  // keep the gauge

  // Landmarks seen by free keyframes, with all their observations in window poses.
  std::unordered_map<LandmarkId, int> point_index;
  std::vector<LandmarkId> point_lm;
  struct Ref { LandmarkId lm; std::size_t obs; };
  std::vector<Ref> refs;
  for (std::size_t k = first_free; k < kfs->size(); ++k)
    for (LandmarkId id : (*kfs)[k].keypoint_landmark) {
      if (id == kInvalidId || point_index.count(id)) continue;
      point_index[id] = int(pb.p_W.size());
      pb.p_W.push_back((*lms)[id].p_A);
      point_lm.push_back(id);
    }
  for (std::size_t j = 0; j < point_lm.size(); ++j) {
    const Landmark& l = (*lms)[point_lm[j]];
    for (std::size_t oi = 0; oi < l.observations.size(); ++oi) {
      const Observation& o = l.observations[oi];
      auto it = pose_index.find(o.keyframe);
      if (it == pose_index.end()) continue;
      const Keypoint& kp = (*kfs)[o.keyframe].keypoints[o.keypoint];
      BaObservation b;
      b.pose = it->second;
      b.point = int(j);
      b.uv = Vec2(kp.u, kp.v);
      b.sigma_px = kp.octave < scales.size() ? scales[kp.octave] : 1.0;
      if (kp.depth > 0) b.u_right = std::max(0.0, kp.u - K_.fx * baseline_ / kp.depth);
      pb.observations.push_back(b);
      refs.push_back({point_lm[j], oi});
    }
  }
  for (bool f : pb.pose_fixed) st.fixed_keyframes += f;
  st.free_keyframes = int(pb.T_C_W.size()) - st.fixed_keyframes;
  st.points = int(pb.p_W.size());
  auto res = solveBundleAdjustment(&pb, params_.ba);
  if (!res.ok()) return st;  // degenerate window: keep the tracked estimates
  st.ba_ms = res->time_ms;
  for (std::size_t i = 0; i < pose_kf.size(); ++i)
    if (!pb.pose_fixed[i]) (*kfs)[pose_kf[i]].T_A_C = pb.T_C_W[i].inverse();
  for (std::size_t j = 0; j < point_lm.size(); ++j) (*lms)[point_lm[j]].p_A = pb.p_W[j];
  // 3. Outlier observations leave the map (highest index first per landmark).
  for (std::size_t k = refs.size(); k-- > 0;) {
    if (!res->outlier[k]) continue;
    Landmark& l = (*lms)[refs[k].lm];
    removeObservation(kfs, &l, refs[k].obs);
    ++st.outliers_removed;
    if (l.observations.empty() && l.id < bad_.size()) bad_[l.id] = true;
  }
  return st;
}

}  // namespace hermes
