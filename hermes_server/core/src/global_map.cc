#include "hermes/server/global_map.h"

#include <cstring>
#include <fstream>
#include <iterator>

#include "hermes/core/crc32.h"
#include "hermes/core/wire_format.h"

namespace hermes {
namespace server {
namespace {

constexpr char kMagic[4] = {'H', 'G', 'M', 'P'};
constexpr std::uint32_t kVersion = 1;

class Writer {
 public:
  template <class T>
  void pod(const T& v) {
    const auto* p = reinterpret_cast<const std::uint8_t*>(&v);
    out.insert(out.end(), p, p + sizeof(T));
  }
  void pose(const SE3& T) {
    const Quat q = T.quat();
    for (double v : {q.x(), q.y(), q.z(), q.w()}) pod(v);
    for (int i = 0; i < 3; ++i) pod(T.translation()[i]);
  }
  void key(const KeyframeKey& k) {
    pod(k.agent);
    pod(k.session);
    pod(k.id);
  }
  std::vector<std::uint8_t> out;
};

class Reader {
 public:
  Reader(const std::vector<std::uint8_t>& b, std::size_t end) : bytes(b), end_(end) {}
  template <class T>
  bool pod(T* v) {
    if (pos + sizeof(T) > end_) return false;
    std::memcpy(v, bytes.data() + pos, sizeof(T));
    pos += sizeof(T);
    return true;
  }
  bool pose(SE3* T) {
    double q[4], t[3];
    for (double& v : q)
      if (!pod(&v)) return false;
    for (double& v : t)
      if (!pod(&v)) return false;
    Quat quat(q[3], q[0], q[1], q[2]);
    if (!std::isfinite(quat.norm()) || quat.norm() < 1e-6) return false;
    *T = SE3(quat.normalized(), Vec3(t[0], t[1], t[2]));
    return true;
  }
  bool key(KeyframeKey* k) { return pod(&k->agent) && pod(&k->session) && pod(&k->id); }
  const std::vector<std::uint8_t>& bytes;
  std::size_t pos = 0;
  std::size_t end_;
};

bool sameCamera(const PinholeIntrinsics& a, const PinholeIntrinsics& b) {
  return a.fx == b.fx && a.fy == b.fy && a.cx == b.cx && a.cy == b.cy && a.width == b.width &&
         a.height == b.height;
}

/// The trajectory as one submap (keypoint_landmark rebuilt from the observations).
Submap asSubmap(const TrajectoryMap& traj) {
  Submap s;
  s.header.agent = traj.uuid;
  s.header.session = traj.session;
  std::map<KeyframeId, std::size_t> index;
  for (const auto& [id, kf] : traj.keyframes) {
    std::uint32_t cam = 0;
    while (cam < s.cameras.size() && !sameCamera(s.cameras[cam], kf.camera)) ++cam;
    if (cam == s.cameras.size()) s.cameras.push_back(kf.camera);
    index[id] = s.keyframes.size();
    s.keyframes.push_back(kf.keyframe);
    s.keyframes.back().camera_id = cam;
    auto& kl = s.keyframes.back().keypoint_landmark;
    kl.assign(s.keyframes.back().keypoints.size(), kInvalidId);
  }
  if (!s.keyframes.empty()) {
    s.header.t_start = s.keyframes.front().stamp;
    s.header.t_end = s.keyframes.back().stamp;
  }
  for (const auto& [id, lm] : traj.landmarks) {
    Landmark l = lm.landmark;
    l.observations.clear();
    for (const Observation& o : lm.landmark.observations) {
      auto it = index.find(o.keyframe);
      if (it == index.end()) continue;
      Keyframe& kf = s.keyframes[it->second];
      if (o.keypoint >= kf.keypoints.size() || kf.keypoint_landmark[o.keypoint] != kInvalidId)
        continue;
      kf.keypoint_landmark[o.keypoint] = id;
      l.observations.push_back(o);
    }
    if (!l.observations.empty()) s.landmarks.push_back(std::move(l));
  }
  for (const auto& [ids, e] : traj.odometry)
    if (index.count(e.from) && index.count(e.to)) s.odometry.push_back(e);
  return s;
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

std::vector<Vec3> GlobalMap::landmarkPositionsWorld() const {
  std::vector<Vec3> out;
  for (const auto& [tid, t] : trajectories) {
    if (!t.anchored) continue;
    for (const auto& [id, lm] : t.landmarks) {
      auto k = t.keyframes.find(lm.anchor);
      if (k != t.keyframes.end()) out.push_back(k->second.T_W_C * lm.p_anchor);
    }
  }
  return out;
}

std::vector<std::uint8_t> GlobalMap::toBytes() const {
  Writer w;
  w.out.insert(w.out.end(), kMagic, kMagic + 4);
  w.pod(kVersion);
  w.pod(static_cast<std::uint32_t>(trajectories.size()));
  for (const auto& [tid, t] : trajectories) {
    w.pod(t.agent);
    w.pod(t.session);
    w.pod(static_cast<std::uint8_t>(t.anchored));
    w.pose(t.T_W_A);
    w.pod(static_cast<std::uint64_t>(t.keyframes.size()));
    for (const auto& [id, kf] : t.keyframes) {
      w.pod(id);
      w.pose(kf.T_W_C);
    }
    auto frame = encodeSubmap(asSubmap(t));
    const std::vector<std::uint8_t> bytes = frame ? std::move(*frame) : std::vector<std::uint8_t>{};
    w.pod(static_cast<std::uint64_t>(bytes.size()));
    w.out.insert(w.out.end(), bytes.begin(), bytes.end());
  }
  w.pod(static_cast<std::uint64_t>(loops.size()));
  for (const LoopEdge& l : loops) {
    w.pod(l.id);
    w.key(l.a);
    w.key(l.b);
    w.pose(l.T_a_b);
    for (int i = 0; i < 36; ++i) w.pod(l.information.data()[i]);
    for (int i = 0; i < 36; ++i) w.pod(l.covariance.data()[i]);
    w.pod(static_cast<std::uint8_t>(l.accepted));
  }
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
  Reader r(bytes, bytes.size() - 4);
  r.pos = 4;
  std::uint32_t version = 0, count = 0;
  if (!r.pod(&version) || version != kVersion)
    return Error{where + "unsupported version " + std::to_string(version)};
  if (!r.pod(&count)) return Error{where + "truncated header"};
  GlobalMap map;
  for (std::uint32_t i = 0; i < count; ++i) {
    TrajectoryMap t;
    std::uint8_t anchored = 0;
    std::uint64_t nkf = 0, frame_bytes = 0;
    if (!r.pod(&t.agent) || !r.pod(&t.session) || !r.pod(&anchored) || !r.pose(&t.T_W_A) ||
        !r.pod(&nkf) || nkf > bytes.size())
      return Error{where + "trajectory " + std::to_string(i) + ": bad header"};
    t.anchored = anchored != 0;
    std::map<KeyframeId, SE3> poses;
    for (std::uint64_t k = 0; k < nkf; ++k) {
      KeyframeId id;
      SE3 T;
      if (!r.pod(&id) || !r.pose(&T))
        return Error{where + "trajectory " + std::to_string(i) + ": truncated poses"};
      poses[id] = T;
    }
    if (!r.pod(&frame_bytes) || r.pos + frame_bytes > r.end_)
      return Error{where + "trajectory " + std::to_string(i) + ": truncated submap frame"};
    auto submap = decodeSubmap(bytes.data() + r.pos, frame_bytes);
    if (!submap)
      return Error{where + "trajectory " + std::to_string(i) + ": " + submap.error()};
    r.pos += frame_bytes;
    t.uuid = submap->header.agent;
    for (Keyframe& kf : submap->keyframes) {
      StoredKeyframe sk;
      sk.camera = submap->cameras[kf.camera_id];
      auto p = poses.find(kf.id);
      sk.T_W_C = p != poses.end() ? p->second : kf.T_A_C;
      sk.keyframe = std::move(kf);
      t.keyframes[sk.keyframe.id] = std::move(sk);
    }
    for (Landmark& lm : submap->landmarks) {
      StoredLandmark sl;
      sl.landmark = std::move(lm);
      anchorLandmark(t, &sl);
      t.landmarks[sl.landmark.id] = std::move(sl);
    }
    for (const OdometryEdge& e : submap->odometry) t.odometry[{e.from, e.to}] = e;
    map.trajectories[{t.agent, t.session}] = std::move(t);
  }
  std::uint64_t nloops = 0;
  if (!r.pod(&nloops) || nloops > bytes.size()) return Error{where + "bad loop count"};
  for (std::uint64_t i = 0; i < nloops; ++i) {
    LoopEdge l;
    std::uint8_t acc = 0;
    bool ok = r.pod(&l.id) && r.key(&l.a) && r.key(&l.b) && r.pose(&l.T_a_b);
    for (int k = 0; ok && k < 36; ++k) ok = r.pod(l.information.data() + k);
    for (int k = 0; ok && k < 36; ++k) ok = r.pod(l.covariance.data() + k);
    if (!ok || !r.pod(&acc)) return Error{where + "loop " + std::to_string(i) + " truncated"};
    l.accepted = acc != 0;
    map.loops.push_back(l);
  }
  if (r.pos != r.end_) return Error{where + "trailing bytes before the CRC"};
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
