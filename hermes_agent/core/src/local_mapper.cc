#include "hermes/agent/local_mapper.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <unordered_map>

#include "hermes/agent/covisibility.h"
#include "hermes/agent/feature_matching.h"

namespace hermes {

Status LocalMapperParams::read(const Config& c) {
  Status s = c.get("mapping.enable_ba", &enable_ba);
  if (!s) return s;
  for (auto [key, ptr] : {std::pair<const char*, int*>{"ba_window", &ba_window},
                          {"max_fixed", &max_fixed},
                          {"min_shared", &min_shared},
                          {"cull_after_keyframes", &cull_after_keyframes},
                          {"min_observations", &min_observations},
                          {"triangulation_keyframes", &triangulation_keyframes},
                          {"max_hamming", &max_hamming}}) {
    s = c.get(std::string("mapping.") + key, ptr);
    if (!s) return s;
  }
  for (auto [key, ptr] : {std::pair<const char*, double*>{"min_found_ratio", &min_found_ratio},
                          {"virtual_baseline", &virtual_baseline},
                          {"min_parallax_deg", &min_parallax_deg}}) {
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
  w->set("mapping.triangulation_keyframes", triangulation_keyframes);
  w->set("mapping.max_hamming", max_hamming);
  w->set("mapping.min_parallax_deg", min_parallax_deg);
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
  if (triangulation_keyframes < 0) return Error{"mapping.triangulation_keyframes must be >= 0"};
  if (max_hamming < 0 || max_hamming > 256) return Error{"mapping.max_hamming must be in [0, 256]"};
  if (!(min_parallax_deg > 0 && min_parallax_deg < 90))
    return Error{"mapping.min_parallax_deg must be in (0, 90)"};
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
  const auto t0 = std::chrono::steady_clock::now();
  LocalMappingStats st;
  processStructure(kfs, lms, scales, &st);
  if (std::optional<LocalBaJob> job = cutBa(*kfs, *lms, scales)) {
    solveLocalBa(&*job);
    applyBa(*job, kfs, lms, &st);
  }
  st.total_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  return st;
}

void LocalMapper::processStructure(std::vector<Keyframe>* kfs, std::vector<Landmark>* lms,
                                   const std::vector<float>& scales, LocalMappingStats* st) {
  if (kfs->empty()) return;
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
      ++st->culled;
    }
  }
  triangulate(kfs, lms, scales, st);
  fuse(kfs, lms, scales, st);
}

std::optional<LocalBaJob> LocalMapper::cutBa(const std::vector<Keyframe>& kfs,
                                             const std::vector<Landmark>& lms,
                                             const std::vector<float>& scales) const {
  if (!params_.enable_ba || kfs.size() < 2) return std::nullopt;
  LocalBaJob job;
  job.newest = kfs.back().id;
  job.T_W_newest = kfs.back().T_A_C;
  job.keyframes = kfs.size();
  job.landmarks = lms.size();
  job.params = params_.ba;
  LocalMappingStats& st = job.stats;

  // 2. Window: newest ba_window keyframes free, covisible older ones fixed.
  const std::size_t first_free =
      kfs.size() > std::size_t(params_.ba_window) ? kfs.size() - params_.ba_window : 0;
  std::unordered_map<KeyframeId, int> pose_index;
  BaProblem& pb = job.problem;
  pb.K = K_;
  pb.baseline = baseline_;
  auto addPose = [&](KeyframeId k, bool fixed) {
    if (pose_index.count(k)) return;
    pose_index[k] = int(pb.T_C_W.size());
    pb.T_C_W.push_back(kfs[k].T_A_C.inverse());
    pb.pose_fixed.push_back(fixed);
    job.pose_kf.push_back(k);
  };
  for (std::size_t k = first_free; k < kfs.size(); ++k) addPose(k, k == 0);
  std::unordered_map<KeyframeId, int> fixed_votes;
  for (std::size_t k = first_free; k < kfs.size(); ++k)
    for (const auto& [other, n] : covisibleKeyframes(kfs, lms, k, params_.min_shared))
      if (other < first_free) fixed_votes[other] += n;
  std::vector<std::pair<int, KeyframeId>> fixed;
  for (const auto& [k, n] : fixed_votes) fixed.emplace_back(n, k);
  std::sort(fixed.rbegin(), fixed.rend());
  if (int(fixed.size()) > params_.max_fixed) fixed.resize(params_.max_fixed);
  for (const auto& f : fixed) addPose(f.second, true);
  if (fixed.empty() && first_free > 0) addPose(first_free - 1, true);  // keep the gauge

  // Landmarks seen by free keyframes, with all their observations in window poses.
  std::unordered_map<LandmarkId, int> point_index;
  for (std::size_t k = first_free; k < kfs.size(); ++k)
    for (LandmarkId id : kfs[k].keypoint_landmark) {
      if (id == kInvalidId || point_index.count(id)) continue;
      point_index[id] = int(pb.p_W.size());
      pb.p_W.push_back(lms[id].p_A);
      job.point_lm.push_back(id);
    }
  for (std::size_t j = 0; j < job.point_lm.size(); ++j) {
    const Landmark& l = lms[job.point_lm[j]];
    for (std::size_t oi = 0; oi < l.observations.size(); ++oi) {
      const Observation& o = l.observations[oi];
      auto it = pose_index.find(o.keyframe);
      if (it == pose_index.end()) continue;
      const Keypoint& kp = kfs[o.keyframe].keypoints[o.keypoint];
      BaObservation b;
      b.pose = it->second;
      b.point = int(j);
      b.uv = Vec2(kp.u, kp.v);
      b.sigma_px = kp.octave < scales.size() ? scales[kp.octave] : 1.0;
      if (kp.depth > 0) b.u_right = K_.rightColumn(kp.u, kp.depth, baseline_);
      pb.observations.push_back(b);
      job.refs.push_back({job.point_lm[j], o.keyframe, o.keypoint});
    }
  }
  for (bool f : pb.pose_fixed) st.fixed_keyframes += f;
  st.free_keyframes = int(pb.T_C_W.size()) - st.fixed_keyframes;
  st.points = int(pb.p_W.size());
  st.observations = int(pb.observations.size());
  for (const BaObservation& o : pb.observations) st.residuals += o.u_right >= 0 ? 3 : 2;
  return job;
}

void solveLocalBa(LocalBaJob* job) {
  if (job->before_solve) job->before_solve();
  auto res = solveBundleAdjustment(&job->problem, job->params);
  if (!res.ok()) return;  // degenerate window: the map keeps the tracked estimates
  job->stats.ba_ms = res->time_ms;
  job->stats.ba_iterations = res->iterations;
  job->summary = std::move(*res);
}

void LocalMapper::applyBa(const LocalBaJob& job, std::vector<Keyframe>* kfs,
                          std::vector<Landmark>* lms, LocalMappingStats* st) {
  st->free_keyframes = job.stats.free_keyframes;
  st->fixed_keyframes = job.stats.fixed_keyframes;
  st->points = job.stats.points;
  st->observations = job.stats.observations;
  st->residuals = job.stats.residuals;
  if (!job.summary) return;
  st->ba_ms = job.stats.ba_ms;
  st->ba_iterations = job.stats.ba_iterations;
  const BaProblem& pb = job.problem;
  for (std::size_t i = 0; i < job.pose_kf.size(); ++i)
    if (!pb.pose_fixed[i]) (*kfs)[job.pose_kf[i]].T_A_C = pb.T_C_W[i].inverse();
  for (std::size_t j = 0; j < job.point_lm.size(); ++j)
    if (!isBad(job.point_lm[j])) (*lms)[job.point_lm[j]].p_A = pb.p_W[j];
  // 3. Outlier observations leave the map (highest index first per landmark).
  const std::vector<bool>& outlier = job.summary->outlier;
  for (std::size_t k = job.refs.size(); k-- > 0;) {
    if (!outlier[k]) continue;
    const LocalBaJob::Ref& ref = job.refs[k];
    Landmark& l = (*lms)[ref.lm];
    auto it = std::find_if(l.observations.begin(), l.observations.end(), [&](const Observation& o) {
      return o.keyframe == ref.keyframe && o.keypoint == ref.keypoint;
    });
    if (it == l.observations.end()) continue;  // fused or culled since the cut
    removeObservation(kfs, &l, std::size_t(it - l.observations.begin()));
    ++st->outliers_removed;
    if (l.observations.empty() && l.id < bad_.size()) bad_[l.id] = true;
  }
  // Keyframes and landmarks created after the cut follow the newest keyframe.
  if (job.keyframes >= kfs->size() && job.landmarks >= lms->size()) return;
  const SE3 correction = (*kfs)[job.newest].T_A_C * job.T_W_newest.inverse();  // W <- W
  for (std::size_t k = job.keyframes; k < kfs->size(); ++k)
    (*kfs)[k].T_A_C = correction * (*kfs)[k].T_A_C;
  for (std::size_t id = job.landmarks; id < lms->size(); ++id)
    if (!isBad(id)) (*lms)[id].p_A = correction * (*lms)[id].p_A;
}

void LocalMapper::fuse(std::vector<Keyframe>* kfs, std::vector<Landmark>* lms,
                       const std::vector<float>& scales, LocalMappingStats* st) {
  Keyframe& kn = kfs->back();
  const SE3 T_N_W = kn.T_A_C.inverse();
  std::vector<LandmarkId> candidates;
  for (const auto& [k, n] : covisibleKeyframes(*kfs, *lms, kn.id, params_.min_shared))
    for (LandmarkId id : (*kfs)[k].keypoint_landmark)
      if (id != kInvalidId && !isBad(id)) candidates.push_back(id);
  std::sort(candidates.begin(), candidates.end());
  candidates.erase(std::unique(candidates.begin(), candidates.end()), candidates.end());
  // Keypoints near a projection come from a grid (a superset of the gate of
  // the largest octave), then are scanned in index order exactly as a scan of
  // every keypoint would (same choice, far fewer distance checks).
  const KeypointGrid grid(kn.keypoints, K_.width, K_.height);
  float max_scale = 1.f;
  for (const Keypoint& k : kn.keypoints)
    max_scale = std::max(max_scale, k.octave < scales.size() ? scales[k.octave] : 1.f);
  const double gate_px = std::sqrt(5.991 * double(max_scale) * double(max_scale)) * (1 + 1e-9) + 1e-6;
  std::vector<int> near;
  for (LandmarkId id : candidates) {
    Landmark& l = (*lms)[id];
    if (isBad(id) || l.observations.empty()) continue;
    bool seen = false;
    for (const Observation& o : l.observations) seen = seen || o.keyframe == kn.id;
    if (seen) continue;
    const Vec3 pc = T_N_W * l.p_A;
    if (pc.z() <= 0.05) continue;
    const Vec2 uv = K_.project(pc);
    if (!K_.inImage(uv)) continue;
    int best = params_.max_hamming + 1;
    std::uint32_t best_i = 0;
    near = grid.query(uv.x(), uv.y(), gate_px);
    std::sort(near.begin(), near.end());
    for (int ni : near) {
      const std::uint32_t i = std::uint32_t(ni);
      const Keypoint& k = kn.keypoints[i];
      const float sg = k.octave < scales.size() ? scales[k.octave] : 1.f;
      if ((Vec2(k.u, k.v) - uv).squaredNorm() > 5.991 * sg * sg) continue;
      const int d = hammingDistance(l.descriptor, kn.descriptors[i]);
      if (d < best) {
        best = d;
        best_i = i;
      }
    }
    if (best > params_.max_hamming) continue;
    const LandmarkId other = kn.keypoint_landmark[best_i];
    if (other == kInvalidId) {
      l.observations.push_back({kn.id, best_i});
      kn.keypoint_landmark[best_i] = id;
      ++st->fused;
      continue;
    }
    if (other == id) continue;
    // Merge the landmark with fewer observations into the other one.
    Landmark& a = (*lms)[id];
    Landmark& b = (*lms)[other];
    Landmark& keep = a.observations.size() >= b.observations.size() ? a : b;
    Landmark& drop = &keep == &a ? b : a;
    for (const Observation& o : drop.observations) {
      Keyframe& kf = (*kfs)[o.keyframe];
      bool has = false;
      for (const Observation& q : keep.observations) has = has || q.keyframe == o.keyframe;
      if (has) {
        kf.keypoint_landmark[o.keypoint] = kInvalidId;
      } else {
        kf.keypoint_landmark[o.keypoint] = keep.id;
        keep.observations.push_back(o);
      }
    }
    drop.observations.clear();
    if (drop.id < bad_.size()) bad_[drop.id] = true;
    if (keep.id < visible_.size() && drop.id < visible_.size()) {
      visible_[keep.id] += visible_[drop.id];
      found_[keep.id] += found_[drop.id];
    }
    ++st->fused;
  }
}

void LocalMapper::triangulate(std::vector<Keyframe>* kfs, std::vector<Landmark>* lms,
                              const std::vector<float>& scales, LocalMappingStats* st) {
  Keyframe& kn = kfs->back();
  auto sigma = [&](const Keypoint& k) { return k.octave < scales.size() ? scales[k.octave] : 1.f; };
  const double cos_min = std::cos(params_.min_parallax_deg * M_PI / 180);
  const auto cov = covisibleKeyframes(*kfs, *lms, kn.id, params_.min_shared);
  const SE3 T_W_N = kn.T_A_C, T_N_W = T_W_N.inverse();
  for (int c = 0; c < int(cov.size()) && c < params_.triangulation_keyframes; ++c) {
    Keyframe& kk = (*kfs)[cov[c].first];
    const SE3 T_W_K = kk.T_A_C, T_K_W = T_W_K.inverse();
    const SE3 T_K_N = T_K_W * T_W_N;
    if (T_K_N.translation().norm() < 1e-3) continue;
    const Mat3 E = hat(T_K_N.translation()) * T_K_N.rotation();  // x_K^T E x_N = 0
    // Free keypoints of kk with their normalised coordinates and epipolar gates,
    // computed once per keyframe pair instead of once per keypoint pair.
    std::vector<std::uint32_t> free_k;
    std::vector<Vec3> free_x;
    std::vector<double> free_gate;
    for (std::uint32_t j = 0; j < kk.keypoints.size(); ++j) {
      if (kk.keypoint_landmark[j] != kInvalidId) continue;
      const Keypoint& b = kk.keypoints[j];
      free_k.push_back(j);
      free_x.emplace_back((b.u - K_.cx) / K_.fx, (b.v - K_.cy) / K_.fy, 1);
      free_gate.push_back(2.0 * 1.96 * sigma(b));
    }
    for (std::uint32_t i = 0; i < kn.keypoints.size(); ++i) {
      if (kn.keypoint_landmark[i] != kInvalidId) continue;
      const Keypoint& a = kn.keypoints[i];
      const Vec3 xn((a.u - K_.cx) / K_.fx, (a.v - K_.cy) / K_.fy, 1);
      const Vec3 line = E * xn;
      const double line_norm = line.head<2>().norm();
      int best = 257, second = 257;
      std::uint32_t best_j = 0;
      for (std::size_t f = 0; f < free_k.size(); ++f) {
        const std::uint32_t j = free_k[f];
        if (kk.keypoint_landmark[j] != kInvalidId) continue;
        // Epipolar distance in pixels (normalised distance · fx).
        if (std::abs(free_x[f].dot(line)) / line_norm * K_.fx > free_gate[f]) continue;
        const int d = hammingDistance(kn.descriptors[i], kk.descriptors[j]);
        if (d < best) {
          second = best;
          best = d;
          best_j = j;
        } else if (d < second) {
          second = d;
        }
      }
      if (best > params_.max_hamming || best > 0.7 * second) continue;
      const Keypoint& b = kk.keypoints[best_j];
      // Midpoint triangulation of the two world rays.
      const Vec3 fn = T_W_N.rotation() * K_.bearing(Vec2(a.u, a.v));
      const Vec3 fk = T_W_K.rotation() * K_.bearing(Vec2(b.u, b.v));
      if (fn.dot(fk) > cos_min) continue;  // too little parallax
      const Vec3 on = T_W_N.translation(), ok = T_W_K.translation();
      Eigen::Matrix<double, 3, 2> A;
      A << fn, -fk;
      const Vec2 s = A.colPivHouseholderQr().solve(ok - on);
      if (!(s[0] > 0 && s[1] > 0)) continue;
      const Vec3 p = 0.5 * (on + s[0] * fn + ok + s[1] * fk);
      const Vec3 pn = T_N_W * p, pk = T_K_W * p;
      if (pn.z() <= 0 || pk.z() <= 0) continue;
      const double en = (K_.project(pn) - Vec2(a.u, a.v)).norm() / sigma(a);
      const double ek = (K_.project(pk) - Vec2(b.u, b.v)).norm() / sigma(b);
      if (en > 2.45 || ek > 2.45) continue;
      Landmark l;
      l.id = lms->size();
      l.p_A = p;
      l.descriptor = kn.descriptors[i];
      l.observations = {{kk.id, best_j}, {kn.id, i}};
      kn.keypoint_landmark[i] = l.id;
      kk.keypoint_landmark[best_j] = l.id;
      noteCreated(l.id, kn.id);
      st->triangulated.emplace_back(l.id, i);
      lms->push_back(std::move(l));
    }
  }
}

}  // namespace hermes
