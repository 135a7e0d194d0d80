#include "hermes/agent/submap_window.h"

#include <algorithm>
#include <unordered_map>
#include <unordered_set>

#include "hermes/agent/covisibility.h"

namespace hermes {

Status SubmapWindowParams::read(const Config& c) {
  if (Status s = c.get("window.period_s", &period_s); !s) return s;
  if (Status s = odometry.read(c); !s) return s;
  return validate();
}

void SubmapWindowParams::write(ConfigWriter* w) const {
  w->set("window.period_s", period_s);
  odometry.write(w);
}

Status SubmapWindowParams::validate() const {
  if (!(period_s > 0)) return Error{"window.period_s must be > 0"};
  if (Status s = odometry.validate(); !s) return Error{"odometry: " + s.error()};
  return Status::Ok();
}

Submap buildWindow(const std::vector<Keyframe>& kfs, const std::vector<Landmark>& lms,
                   const std::vector<char>& lost_before, std::size_t first, std::size_t last,
                   const PinholeIntrinsics& K, SubmapHeader header,
                   const SubmapWindowParams& params) {
  Submap s;
  last = std::min(last, kfs.size());
  s.cameras = {K};
  if (first >= last) {
    s.header = header;
    return s;
  }
  header.t_start = kfs[first].stamp;
  header.t_end = kfs[last - 1].stamp;
  s.header = header;
  std::unordered_map<LandmarkId, std::size_t> lm_index;
  for (std::size_t k = first; k < last; ++k) {
    Keyframe kf = kfs[k];
    kf.camera_id = 0;
    kf.lost_before = k < lost_before.size() && lost_before[k];
    for (std::size_t i = 0; i < kf.keypoint_landmark.size(); ++i) {
      const LandmarkId id = kf.keypoint_landmark[i];
      if (id == kInvalidId || id >= lms.size() || lms[id].observations.empty()) {
        kf.keypoint_landmark[i] = kInvalidId;
        continue;
      }
      if (lm_index.emplace(id, s.landmarks.size()).second) {
        Landmark l;
        l.id = id;
        l.p_A = lms[id].p_A;
        l.descriptor = lms[id].descriptor;
        for (const Observation& o : lms[id].observations)
          if (o.keyframe >= first && o.keyframe < last) l.observations.push_back(o);
        s.landmarks.push_back(std::move(l));
      }
    }
    s.keyframes.push_back(std::move(kf));
  }
  for (std::size_t k = first + 1; k < last; ++k) {
    OdometryEdge e;
    e.from = kfs[k - 1].id;
    e.to = kfs[k].id;
    e.T_from_to = kfs[k - 1].T_A_C.inverse() * kfs[k].T_A_C;
    const bool lost = k < lost_before.size() && lost_before[k];
    e.information = odometryInformation(e.T_from_to, sharedLandmarks(kfs, lms, k - 1, k), lost,
                                        params.odometry);
    s.odometry.push_back(e);
  }
  return s;
}

Expected<Submap> mergeWindows(Submap earlier, const Submap& later) {
  if (earlier.cameras.size() != later.cameras.size())
    return Error{"cannot merge windows with different camera tables"};
  for (std::size_t i = 0; i < later.cameras.size(); ++i) {
    const PinholeIntrinsics &a = earlier.cameras[i], &b = later.cameras[i];
    if (a.fx != b.fx || a.fy != b.fy || a.cx != b.cx || a.cy != b.cy || a.width != b.width ||
        a.height != b.height)
      return Error{"cannot merge windows with different camera tables"};
  }
  Submap out = std::move(earlier);
  const double t_start = out.keyframes.empty() ? later.header.t_start : out.header.t_start;
  out.header = later.header;
  out.header.t_start = t_start;
  out.keyframes.insert(out.keyframes.end(), later.keyframes.begin(), later.keyframes.end());
  std::unordered_map<LandmarkId, std::size_t> index;
  for (std::size_t i = 0; i < out.landmarks.size(); ++i) index.emplace(out.landmarks[i].id, i);
  for (const Landmark& l : later.landmarks) {
    auto it = index.find(l.id);
    if (it == index.end()) {
      index.emplace(l.id, out.landmarks.size());
      out.landmarks.push_back(l);
      continue;
    }
    Landmark& m = out.landmarks[it->second];
    m.p_A = l.p_A;
    m.descriptor = l.descriptor;
    m.observations.insert(m.observations.end(), l.observations.begin(), l.observations.end());
  }
  out.odometry.insert(out.odometry.end(), later.odometry.begin(), later.odometry.end());
  return out;
}

std::size_t keepNewestKeyframes(Submap* s, std::size_t max_keyframes) {
  if (s->keyframes.size() <= max_keyframes) return 0;
  const std::size_t drop = s->keyframes.size() - max_keyframes;
  std::unordered_set<KeyframeId> dropped;
  bool lost = false;  // a loss before a dropped keyframe is one before the new first
  for (std::size_t i = 0; i <= drop; ++i) {
    lost = lost || s->keyframes[i].lost_before;
    if (i < drop) dropped.insert(s->keyframes[i].id);
  }
  s->keyframes[drop].lost_before = lost;
  s->keyframes.erase(s->keyframes.begin(), s->keyframes.begin() + static_cast<std::ptrdiff_t>(drop));
  std::vector<Landmark> kept;
  for (Landmark& l : s->landmarks) {
    std::vector<Observation> obs;
    for (const Observation& o : l.observations)
      if (!dropped.count(o.keyframe)) obs.push_back(o);
    if (obs.empty()) continue;
    l.observations = std::move(obs);
    kept.push_back(std::move(l));
  }
  s->landmarks = std::move(kept);
  std::unordered_set<LandmarkId> alive;
  for (const Landmark& l : s->landmarks) alive.insert(l.id);
  for (Keyframe& kf : s->keyframes)
    for (LandmarkId& id : kf.keypoint_landmark)
      if (id != kInvalidId && !alive.count(id)) id = kInvalidId;
  std::vector<OdometryEdge> edges;
  for (const OdometryEdge& e : s->odometry)
    if (!dropped.count(e.from) && !dropped.count(e.to)) edges.push_back(e);
  s->odometry = std::move(edges);
  if (!s->keyframes.empty()) s->header.t_start = s->keyframes.front().stamp;
  return drop;
}

}  // namespace hermes
