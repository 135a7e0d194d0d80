#include "hermes/server/global_map.h"

#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>

#include "hermes/core/crc32.h"
#include "hermes/server/byte_codec.h"

namespace hermes {
namespace server {
namespace {

constexpr char kMagic[4] = {'H', 'G', 'M', 'P'};
// 1: trajectories as wire-format submap frames (lossy: float information,
//    observations rebuilt). 2: every field as stored, loops with inliers.
// 3: + loop inlier keypoint pairs, refined edges (map refinement).
constexpr std::uint32_t kVersion = 4;
constexpr std::size_t kKeypointBytes = 4 + 4 + 1 + 4 + 32 + 8;  // + descriptor + landmark

void writeCamera(ByteWriter* w, const PinholeIntrinsics& c) {
  for (double v : {c.fx, c.fy, c.cx, c.cy}) w->pod(v);
  w->pod(static_cast<std::int32_t>(c.width));
  w->pod(static_cast<std::int32_t>(c.height));
}

bool readCamera(ByteReader* r, PinholeIntrinsics* c) {
  std::int32_t width = 0, height = 0;
  if (!r->pod(&c->fx) || !r->pod(&c->fy) || !r->pod(&c->cx) || !r->pod(&c->cy) ||
      !r->pod(&width) || !r->pod(&height))
    return false;
  c->width = width;
  c->height = height;
  return std::isfinite(c->fx) && std::isfinite(c->fy) && std::isfinite(c->cx) &&
         std::isfinite(c->cy) && c->fx > 0 && c->fy > 0 && width > 0 && height > 0;
}

void writeKeyframe(ByteWriter* w, const StoredKeyframe& sk) {
  const Keyframe& kf = sk.keyframe;
  w->pod(kf.id);
  w->pod(kf.stamp);
  w->pose(kf.T_A_C);
  w->pod(kf.camera_id);
  w->flag(kf.lost_before);
  writeCamera(w, sk.camera);
  w->pose(sk.T_W_C);
  w->count(kf.keypoints.size());
  for (const Keypoint& k : kf.keypoints) {
    w->pod(k.u);
    w->pod(k.v);
    w->pod(k.octave);
    w->pod(k.depth);
  }
  for (const Descriptor& d : kf.descriptors) w->pod(d);
  for (LandmarkId l : kf.keypoint_landmark) w->pod(l);
}

bool readKeyframe(ByteReader* r, StoredKeyframe* sk) {
  Keyframe& kf = sk->keyframe;
  std::uint64_t n = 0;
  if (!r->pod(&kf.id) || !r->pod(&kf.stamp) || !std::isfinite(kf.stamp) || !r->pose(&kf.T_A_C) ||
      !r->pod(&kf.camera_id) || !r->flag(&kf.lost_before) || !readCamera(r, &sk->camera) ||
      !r->pose(&sk->T_W_C) || !r->count(&n, kKeypointBytes))
    return false;
  kf.keypoints.resize(n);
  kf.descriptors.resize(n);
  kf.keypoint_landmark.resize(n);
  for (Keypoint& k : kf.keypoints)
    if (!r->pod(&k.u) || !r->pod(&k.v) || !r->pod(&k.octave) || !r->pod(&k.depth) ||
        !std::isfinite(k.u) || !std::isfinite(k.v) || !std::isfinite(k.depth))
      return false;
  for (Descriptor& d : kf.descriptors)
    if (!r->pod(&d)) return false;
  for (LandmarkId& l : kf.keypoint_landmark)
    if (!r->pod(&l)) return false;
  return true;
}

void writeLandmark(ByteWriter* w, const StoredLandmark& sl) {
  const Landmark& l = sl.landmark;
  w->pod(l.id);
  w->vec3(l.p_A);
  w->pod(l.descriptor);
  w->pod(sl.anchor);
  w->vec3(sl.p_anchor);
  w->count(l.observations.size());
  for (const Observation& o : l.observations) {
    w->pod(o.keyframe);
    w->pod(o.keypoint);
  }
}

bool readLandmark(ByteReader* r, StoredLandmark* sl) {
  Landmark& l = sl->landmark;
  std::uint64_t n = 0;
  if (!r->pod(&l.id) || !r->vec3(&l.p_A) || !r->pod(&l.descriptor) || !r->pod(&sl->anchor) ||
      !r->vec3(&sl->p_anchor) || !r->count(&n, 12))
    return false;
  l.observations.resize(n);
  for (Observation& o : l.observations)
    if (!r->pod(&o.keyframe) || !r->pod(&o.keypoint)) return false;
  return true;
}

void writeTrajectory(ByteWriter* w, const TrajectoryMap& t) {
  w->pod(t.agent);
  w->pod(t.session);
  w->pod(t.uuid);
  w->flag(t.anchored);
  w->pose(t.T_W_A);
  w->count(t.keyframes.size());
  for (const auto& [id, kf] : t.keyframes) writeKeyframe(w, kf);
  w->count(t.landmarks.size());
  for (const auto& [id, lm] : t.landmarks) writeLandmark(w, lm);
  w->count(t.odometry.size());
  for (const auto& [ids, e] : t.odometry) {
    w->pod(e.from);
    w->pod(e.to);
    w->pose(e.T_from_to);
    w->mat6(e.information);
  }
}

/// Reads one trajectory; the reason names what is wrong.
Status readTrajectory(ByteReader* r, TrajectoryMap* t) {
  std::uint64_t n = 0;
  if (!r->pod(&t->agent) || !r->pod(&t->session) || !r->pod(&t->uuid) || !r->flag(&t->anchored) ||
      !r->pose(&t->T_W_A) || !r->count(&n, 100))
    return Error{"bad header"};
  for (std::uint64_t i = 0; i < n; ++i) {
    StoredKeyframe sk;
    if (!readKeyframe(r, &sk)) return Error{"keyframe " + std::to_string(i) + " damaged"};
    const KeyframeId id = sk.keyframe.id;
    if (!t->keyframes.emplace(id, std::move(sk)).second)
      return Error{"keyframe id " + std::to_string(id) + " twice"};
  }
  if (!r->count(&n, 60)) return Error{"bad landmark count"};
  for (std::uint64_t i = 0; i < n; ++i) {
    StoredLandmark sl;
    if (!readLandmark(r, &sl)) return Error{"landmark " + std::to_string(i) + " damaged"};
    if (sl.anchor != kInvalidId && !t->keyframes.count(sl.anchor))
      return Error{"landmark " + std::to_string(sl.landmark.id) + " anchored to unknown keyframe " +
                   std::to_string(sl.anchor)};
    for (const Observation& o : sl.landmark.observations) {
      auto k = t->keyframes.find(o.keyframe);
      if (k != t->keyframes.end() && o.keypoint >= k->second.keyframe.keypoints.size())
        return Error{"landmark " + std::to_string(sl.landmark.id) + " observes keypoint " +
                     std::to_string(o.keypoint) + " of keyframe " + std::to_string(o.keyframe) +
                     ", which has fewer"};
    }
    const LandmarkId id = sl.landmark.id;
    if (!t->landmarks.emplace(id, std::move(sl)).second)
      return Error{"landmark id " + std::to_string(id) + " twice"};
  }
  if (!r->count(&n, 16 + 56 + 288)) return Error{"bad odometry count"};
  for (std::uint64_t i = 0; i < n; ++i) {
    OdometryEdge e;
    if (!r->pod(&e.from) || !r->pod(&e.to) || !r->pose(&e.T_from_to) || !r->mat6(&e.information))
      return Error{"odometry edge " + std::to_string(i) + " damaged"};
    if (!t->odometry.emplace(std::make_pair(e.from, e.to), e).second)
      return Error{"odometry edge " + std::to_string(e.from) + "->" + std::to_string(e.to) + " twice"};
  }
  return Status::Ok();
}

void writeLoop(ByteWriter* w, const LoopEdge& l) {
  w->pod(l.id);
  w->key(l.a);
  w->key(l.b);
  w->pose(l.T_a_b);
  w->mat6(l.information);
  w->mat6(l.covariance);
  w->flag(l.accepted);
  w->pod(static_cast<std::int32_t>(l.inliers));
  w->pod(static_cast<std::int32_t>(l.depth_inliers));
  w->count(l.matches.size());
  for (const LoopMatch& m : l.matches) {
    w->pod(m.kf_a);
    w->pod(m.kp_a);
    w->pod(m.kf_b);
    w->pod(m.kp_b);
  }
}

bool readLoop(ByteReader* r, LoopEdge* l) {
  std::int32_t inliers = 0, depth_inliers = 0;
  if (!r->pod(&l->id) || !r->key(&l->a) || !r->key(&l->b) || !r->pose(&l->T_a_b) ||
      !r->mat6(&l->information) || !r->mat6(&l->covariance) || !r->flag(&l->accepted) ||
      !r->pod(&inliers) || !r->pod(&depth_inliers))
    return false;
  l->inliers = inliers;
  l->depth_inliers = depth_inliers;
  std::uint64_t n = 0;
  if (!r->count(&n, 24)) return false;
  l->matches.resize(n);
  for (LoopMatch& m : l->matches)
    if (!r->pod(&m.kf_a) || !r->pod(&m.kp_a) || !r->pod(&m.kf_b) || !r->pod(&m.kp_b)) return false;
  return true;
}

/// A loop's kept keypoint pairs name keyframes and keypoints the map holds.
bool matchesValid(const GlobalMap& map, const LoopEdge& l) {
  for (const LoopMatch& m : l.matches) {
    const StoredKeyframe* a = map.keyframe(KeyframeKey{l.a.agent, l.a.session, m.kf_a});
    const StoredKeyframe* b = map.keyframe(KeyframeKey{l.b.agent, l.b.session, m.kf_b});
    if (!a || !b || m.kp_a >= a->keyframe.keypoints.size() || m.kp_b >= b->keyframe.keypoints.size())
      return false;
  }
  return true;
}

}  // namespace

const StoredKeyframe* GlobalMap::keyframe(const KeyframeKey& key) const {
  auto t = trajectories.find({key.agent, key.session});
  if (t == trajectories.end()) return nullptr;
  auto k = t->second.keyframes.find(key.id);
  return k == t->second.keyframes.end() ? nullptr : &k->second;
}

StoredKeyframe* GlobalMap::keyframe(const KeyframeKey& key) {
  return const_cast<StoredKeyframe*>(static_cast<const GlobalMap*>(this)->keyframe(key));
}

const TrajectoryMap* GlobalMap::trajectory(std::uint32_t agent, std::uint32_t session) const {
  auto t = trajectories.find({agent, session});
  return t == trajectories.end() ? nullptr : &t->second;
}

std::size_t GlobalMap::keyframeCount() const {
  std::size_t n = 0;
  for (const auto& [id, t] : trajectories) n += t.keyframes.size();
  return n;
}

std::size_t GlobalMap::landmarkCount() const {
  std::size_t n = 0;
  for (const auto& [id, t] : trajectories) n += t.landmarks.size();
  return n;
}

void GlobalMap::anchorLandmark(const TrajectoryMap& traj, StoredLandmark* lm) {
  for (const Observation& o : lm->landmark.observations) {
    auto k = traj.keyframes.find(o.keyframe);
    if (k == traj.keyframes.end()) continue;
    lm->anchor = o.keyframe;
    lm->p_anchor = k->second.keyframe.T_A_C.inverse() * lm->landmark.p_A;
    return;
  }
  lm->anchor = kInvalidId;
}

std::vector<Vec3> GlobalMap::landmarkPositionsWorld(std::vector<std::uint32_t>* robots) const {
  std::vector<Vec3> out;
  if (robots) robots->clear();
  for (const auto& [tid, t] : trajectories) {
    if (!t.anchored) continue;
    for (const auto& [id, lm] : t.landmarks) {
      auto k = t.keyframes.find(lm.anchor);
      if (k == t.keyframes.end()) continue;
      out.push_back(k->second.T_W_C * lm.p_anchor);
      if (robots) robots->push_back(t.agent);
    }
  }
  return out;
}

std::vector<std::uint8_t> GlobalMap::toBytes() const {
  ByteWriter w;
  w.out.assign(kMagic, kMagic + 4);
  w.pod(kVersion);
  w.count(trajectories.size());
  for (const auto& [tid, t] : trajectories) writeTrajectory(&w, t);
  w.count(loops.size());
  for (const LoopEdge& l : loops) writeLoop(&w, l);
  w.pod(crc32(w.out.data(), w.out.size()));
  return w.out;
}

Expected<GlobalMap> GlobalMap::fromBytes(const std::vector<std::uint8_t>& bytes,
                                         const std::string& origin) {
  const std::string where = "global map " + origin + ": ";
  if (bytes.size() < 12 || std::memcmp(bytes.data(), kMagic, 4) != 0)
    return Error{where + "not a global map file (bad magic or too short)"};
  std::uint32_t stored_crc;
  std::memcpy(&stored_crc, bytes.data() + bytes.size() - 4, 4);
  if (crc32(bytes.data(), bytes.size() - 4) != stored_crc) return Error{where + "CRC mismatch"};
  ByteReader r(bytes.data() + 4, bytes.size() - 8);
  std::uint32_t version = 0;
  std::uint64_t count = 0;
  if (!r.pod(&version) || version != kVersion)
    return Error{where + "unsupported version " + std::to_string(version) + " (this build reads " +
                 std::to_string(kVersion) + ")"};
  if (!r.count(&count, 48)) return Error{where + "bad trajectory count"};
  GlobalMap map;
  for (std::uint64_t i = 0; i < count; ++i) {
    TrajectoryMap t;
    if (Status s = readTrajectory(&r, &t); !s)
      return Error{where + "trajectory " + std::to_string(i) + ": " + s.error()};
    const TrajectoryId id{t.agent, t.session};
    if (!map.trajectories.emplace(id, std::move(t)).second)
      return Error{where + "trajectory (" + std::to_string(id.first) + ", " +
                   std::to_string(id.second) + ") twice"};
  }
  if (!r.count(&count, 400)) return Error{where + "bad loop count"};
  for (std::uint64_t i = 0; i < count; ++i) {
    LoopEdge l;
    if (!readLoop(&r, &l)) return Error{where + "loop " + std::to_string(i) + " damaged"};
    if (!map.keyframe(l.a) || !map.keyframe(l.b))
      return Error{where + "loop " + std::to_string(l.id) + " joins a keyframe the map does not hold"};
    if (!matchesValid(map, l))
      return Error{where + "loop " + std::to_string(l.id) + " keeps a keypoint pair the map does not hold"};
    map.loops.push_back(std::move(l));
  }
  if (!r.atEnd()) return Error{where + "trailing bytes before the CRC"};
  return map;
}

Status GlobalMap::save(const std::string& path) const {
  const auto bytes = toBytes();
  std::ofstream f(path, std::ios::binary);
  if (!f) return Error{"global map: cannot write " + path};
  f.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  if (!f) return Error{"global map: write failed for " + path};
  return Status::Ok();
}

Expected<GlobalMap> GlobalMap::load(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) return Error{"global map: cannot open " + path};
  std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(f)),
                                  std::istreambuf_iterator<char>());
  return fromBytes(bytes, path);
}

}  // namespace server
}  // namespace hermes
