#include "hermes/server/downlink.h"

#include <algorithm>
#include <cmath>

#include "hermes/distill/scores.h"

namespace hermes {
namespace server {
namespace {

std::size_t varintBytes(std::uint64_t v) {
  std::size_t n = 1;
  for (; v >= 0x80; v >>= 7) ++n;
  return n;
}
std::size_t keyBytes(const KeyframeKey& k) {
  return varintBytes(k.agent) + varintBytes(k.session) + varintBytes(k.id);
}
// Encoded sizes (map_down.h) as upper bounds: a landmark index costs at most 3
// bytes below 2^21 landmarks, the counts at most 3 each.
constexpr std::size_t kPacketFixedBytes = 4 + 1 + 16 + 8 + 4 + 8 + 56 + 3 + 3 + 4;
std::size_t keyframeBytes(const KeyframeKey& k, std::size_t landmarks) {
  return keyBytes(k) + 8 + 56 + 3 + 3 * landmarks;
}
std::size_t landmarkBytes(const KeyframeKey& k) { return keyBytes(k) + 12 + 32; }

const StoredKeyframe* newestKeyframe(const TrajectoryMap& t, const StoredKeyframe** previous) {
  const StoredKeyframe *newest = nullptr, *before = nullptr;
  for (const auto& [id, kf] : t.keyframes) {
    if (!newest || kf.keyframe.stamp > newest->keyframe.stamp) {
      before = newest;
      newest = &kf;
    } else if (!before || kf.keyframe.stamp > before->keyframe.stamp) {
      before = &kf;
    }
  }
  *previous = before;
  return newest;
}

/// The session the map is sent around: the robot's current one once placed;
/// before that its newest placed earlier session (a robot that lost track gets
/// the map around where it was last placed - its own last keyframes first - and
/// the packets are in that session's odometry frame); none: nothing to send.
const TrajectoryMap* placedSession(const GlobalMap& map, const DownlinkRecipient& who) {
  const auto usable = [](const TrajectoryMap* t) { return t && t->anchored && !t->keyframes.empty(); };
  if (const TrajectoryMap* t = map.trajectory(who.robot, who.session); usable(t)) return t;
  const TrajectoryMap* best = nullptr;
  for (const auto& [tid, t] : map.trajectories)
    if (t.agent == who.robot && t.session < who.session && usable(&t) && (!best || t.session > best->session))
      best = &t;
  return best;
}

struct Candidate {
  double distance = 0;
  const TrajectoryMap* traj = nullptr;
  const StoredKeyframe* kf = nullptr;
  KeyframeKey key;
};

}  // namespace

Status DownlinkParams::read(const Config& c, const std::string& p) {
  for (auto s : {c.get(p + "enabled", &enabled), c.get(p + "bytes_per_s", &bytes_per_s),
                 c.get(p + "burst_s", &burst_s), c.get(p + "radius_m", &radius_m),
                 c.get(p + "landmarks_per_keyframe", &landmarks_per_keyframe),
                 c.get(p + "min_packet_bytes", &min_packet_bytes),
                 c.get(p + "max_packet_bytes", &max_packet_bytes),
                 c.get(p + "max_in_flight", &max_in_flight),
                 c.get(p + "resend_after_s", &resend_after_s)})
    if (!s) return s;
  return validate();
}

void DownlinkParams::write(ConfigWriter& w, const std::string& p) const {
  w.set(p + "enabled", enabled);
  w.set(p + "bytes_per_s", bytes_per_s);
  w.set(p + "burst_s", burst_s);
  w.set(p + "radius_m", radius_m);
  w.set(p + "landmarks_per_keyframe", landmarks_per_keyframe);
  w.set(p + "min_packet_bytes", min_packet_bytes);
  w.set(p + "max_packet_bytes", max_packet_bytes);
  w.set(p + "max_in_flight", max_in_flight);
  w.set(p + "resend_after_s", resend_after_s);
}

Status DownlinkParams::validate() const {
  const std::string p = "server.downlink.";
  if (!(bytes_per_s > 0)) return Error{p + "bytes_per_s must be > 0"};
  if (!(burst_s > 0)) return Error{p + "burst_s must be > 0"};
  if (!(radius_m > 0)) return Error{p + "radius_m must be > 0"};
  if (landmarks_per_keyframe < 1) return Error{p + "landmarks_per_keyframe must be >= 1"};
  if (min_packet_bytes < 256 || max_packet_bytes < min_packet_bytes)
    return Error{p + "min_packet_bytes must be >= 256 and <= max_packet_bytes (" +
                 std::to_string(min_packet_bytes) + ", " + std::to_string(max_packet_bytes) + ")"};
  if (bytes_per_s * burst_s < min_packet_bytes)
    return Error{p + "bytes_per_s * burst_s (the bucket) must hold min_packet_bytes"};
  if (max_in_flight < 1) return Error{p + "max_in_flight must be >= 1"};
  if (!(resend_after_s > 0)) return Error{p + "resend_after_s must be > 0"};
  return Status::Ok();
}

Downlink::Downlink(const DownlinkParams& params, std::uint64_t epoch)
    : params_(params), epoch_(epoch) {}

void Downlink::refill(Robot* r, double now) const {
  const double depth = params_.bytes_per_s * params_.burst_s;
  if (r->refilled_at < 0) {
    r->tokens = depth;
  } else if (now > r->refilled_at) {
    r->tokens = std::min(depth, r->tokens + (now - r->refilled_at) * params_.bytes_per_s);
  }
  r->refilled_at = std::max(now, r->refilled_at);
}

std::vector<Downlink::Outgoing> Downlink::plan(const GlobalMap& map,
                                               const std::vector<DownlinkRecipient>& recipients,
                                               double now) {
  std::vector<Outgoing> out;
  if (!params_.enabled) return out;
  for (const DownlinkRecipient& who : recipients) {
    Robot& r = robots_[who.agent];
    r.id = who.robot;
    refill(&r, now);
    DownlinkRobotStats& st = stats_[who.robot];
    for (auto& [seq, pk] : r.in_flight) {
      const double size = static_cast<double>(pk.bytes->size());
      if (now - pk.sent_at < params_.resend_after_s || r.tokens < size) continue;
      r.tokens -= size;
      pk.sent_at = now;
      st.bytes += pk.bytes->size();
      ++st.resends;
      out.push_back({who.robot, who.agent, seq, true, pk.bytes});
    }
    if (r.in_flight.size() >= static_cast<std::size_t>(params_.max_in_flight) ||
        r.tokens < params_.min_packet_bytes)
      continue;
    const auto cap = static_cast<std::size_t>(
        std::min(r.tokens, static_cast<double>(params_.max_packet_bytes)));
    std::optional<MapDownPacket> p = select(map, who, r, cap);
    if (!p) continue;
    p->agent = who.agent;
    p->epoch = epoch_;
    p->seq = r.next_seq;
    Expected<std::vector<std::uint8_t>> bytes = encodeMapDown(*p);
    if (!bytes) continue;  // select() builds valid packets; nothing to send otherwise
    Packet pk;
    pk.bytes = std::make_shared<const std::vector<std::uint8_t>>(std::move(*bytes));
    pk.sent_at = now;
    for (const BorrowedKeyframe& k : p->keyframes) {
      pk.keyframes.push_back(k.origin);
      r.keyframes_busy.insert(k.origin);
    }
    for (const BorrowedLandmark& l : p->landmarks) {
      pk.landmarks.push_back(l.origin);
      r.landmarks_busy.insert(l.origin);
    }
    r.tokens -= static_cast<double>(pk.bytes->size());
    st.bytes += pk.bytes->size();
    ++st.packets;
    if (st.first_send_s < 0) st.first_send_s = now;
    out.push_back({who.robot, who.agent, r.next_seq, false, pk.bytes});
    r.in_flight.emplace(r.next_seq++, std::move(pk));
  }
  return out;
}

bool Downlink::onAck(const MapDownAck& ack, double /*now*/) {
  if (ack.epoch != epoch_) return false;
  auto rit = robots_.find(ack.agent);
  if (rit == robots_.end()) return false;
  Robot& r = rit->second;
  auto it = r.in_flight.find(ack.seq);
  if (it == r.in_flight.end()) return false;
  DownlinkRobotStats& st = stats_[r.id];
  for (const KeyframeKey& k : it->second.keyframes) {
    r.keyframes_busy.erase(k);
    r.keyframes_held.insert(k);
  }
  for (const KeyframeKey& k : it->second.landmarks) {
    r.landmarks_busy.erase(k);
    r.landmarks_held.insert(k);
  }
  st.keyframes += it->second.keyframes.size();
  st.landmarks += it->second.landmarks.size();
  ++st.acked;
  r.in_flight.erase(it);
  return true;
}

void Downlink::onReconnect(const Uuid& agent) {
  auto it = robots_.find(agent);
  if (it == robots_.end()) return;
  for (auto& [seq, pk] : it->second.in_flight) pk.sent_at = -1e300;
}

std::size_t Downlink::inFlight() const {
  std::size_t n = 0;
  for (const auto& [uuid, r] : robots_) n += r.in_flight.size();
  return n;
}

std::optional<MapDownPacket> Downlink::select(const GlobalMap& map, const DownlinkRecipient& who,
                                              const Robot& r, std::size_t byte_cap) const {
  const TrajectoryMap* own = placedSession(map, who);
  if (own == nullptr) return std::nullopt;
  const StoredKeyframe* prev = nullptr;
  const StoredKeyframe* newest = newestKeyframe(*own, &prev);
  const Vec3 p_r = newest->T_W_C.translation();
  const SE3 T_O_W = (newest->T_W_C * newest->keyframe.T_A_C.inverse()).inverse();

  // The neighbourhood: anchored keyframes of other trajectories not held or on the way.
  std::vector<Candidate> cands;
  for (const auto& [tid, t] : map.trajectories) {
    if (!t.anchored || (t.agent == who.robot && t.session == who.session)) continue;
    for (const auto& [id, kf] : t.keyframes) {
      const double d = (kf.T_W_C.translation() - p_r).norm();
      const KeyframeKey key{t.agent, t.session, id};
      if (d > params_.radius_m || r.keyframes_held.count(key) || r.keyframes_busy.count(key))
        continue;
      cands.push_back({d, &t, &kf, key});
    }
  }
  if (cands.empty()) return std::nullopt;
  std::sort(cands.begin(), cands.end(), [](const Candidate& a, const Candidate& b) {
    return a.distance != b.distance ? a.distance < b.distance : a.key < b.key;
  });
  // No more keyframes than the packet could carry with a few landmarks each.
  const std::size_t room = byte_cap / (keyframeBytes(cands[0].key, 10) + 10 * 48) + 1;
  if (cands.size() > room) cands.resize(room);

  // Score the neighbourhood's landmarks with the uplink's scores: a window in
  // the world frame, keyframes numbered by candidate, landmarks by first sight.
  Submap w;
  w.cameras.push_back(newest->camera);  // camera 0: the robot's, for the hint
  std::map<KeyframeKey, std::size_t> lm_index;  // landmark origin -> index in w
  std::vector<KeyframeKey> lm_origin;
  std::vector<std::vector<std::size_t>> kf_landmarks(cands.size());
  for (std::size_t c = 0; c < cands.size(); ++c) {
    const Candidate& cd = cands[c];
    Keyframe k;
    k.id = c;
    k.stamp = cd.kf->keyframe.stamp;
    k.T_A_C = cd.kf->T_W_C;
    k.camera_id = static_cast<std::uint32_t>(w.cameras.size());
    w.cameras.push_back(cd.kf->camera);
    const Keyframe& src = cd.kf->keyframe;
    for (std::size_t i = 0; i < src.keypoint_landmark.size() && i < src.keypoints.size(); ++i) {
      const LandmarkId lid = src.keypoint_landmark[i];
      if (lid == kInvalidId) continue;
      const KeyframeKey lkey{cd.key.agent, cd.key.session, lid};
      if (r.landmarks_held.count(lkey) || r.landmarks_busy.count(lkey)) continue;
      auto lit = cd.traj->landmarks.find(lid);
      if (lit == cd.traj->landmarks.end() || lit->second.anchor == kInvalidId) continue;
      auto ait = cd.traj->keyframes.find(lit->second.anchor);
      if (ait == cd.traj->keyframes.end()) continue;
      auto [it, fresh] = lm_index.emplace(lkey, w.landmarks.size());
      if (fresh) {
        Landmark l;
        l.id = w.landmarks.size();
        l.p_A = ait->second.T_W_C * lit->second.p_anchor;
        l.descriptor = lit->second.landmark.descriptor;
        w.landmarks.push_back(l);
        lm_origin.push_back(lkey);
      }
      w.landmarks[it->second].observations.push_back(
          {k.id, static_cast<std::uint32_t>(k.keypoints.size())});
      k.keypoints.push_back(src.keypoints[i]);
      kf_landmarks[c].push_back(it->second);
    }
    w.keyframes.push_back(std::move(k));
  }
  distill::MotionHint hint;
  if (prev != nullptr && newest->keyframe.stamp > prev->keyframe.stamp) {
    hint.valid = true;
    hint.T_A_C = newest->T_W_C;
    hint.T_Cprev_Ccurr = prev->T_W_C.inverse() * newest->T_W_C;
    hint.dt_s = newest->keyframe.stamp - prev->keyframe.stamp;
    hint.camera_id = 0;
  }
  const distill::LandmarkScores scores = distill::computeScores(w, hint, 0, distill::DistillParams{});

  // Fill nearest keyframe first with its best landmarks, within the cap.
  MapDownPacket p;
  p.session = own->session;
  p.T_W_O = T_O_W.inverse();
  std::map<std::size_t, std::uint32_t> in_packet;  // w index -> packet index
  std::size_t bytes = kPacketFixedBytes;
  for (std::size_t c = 0; c < cands.size(); ++c) {
    std::vector<std::size_t> mine = kf_landmarks[c];
    std::sort(mine.begin(), mine.end(), [&](std::size_t a, std::size_t b) {
      return scores.value[a] != scores.value[b] ? scores.value[a] > scores.value[b] : a < b;
    });
    BorrowedKeyframe bk;
    bk.origin = cands[c].key;
    bk.stamp = cands[c].kf->keyframe.stamp;
    bk.T_O_C = T_O_W * cands[c].kf->T_W_C;
    std::vector<std::size_t> add;
    std::size_t kf_bytes = keyframeBytes(bk.origin, 0), lm_bytes = 0;
    for (std::size_t idx : mine) {
      if (static_cast<int>(bk.landmarks.size() + add.size()) >= params_.landmarks_per_keyframe) break;
      auto it = in_packet.find(idx);
      const std::size_t extra = 3 + (it == in_packet.end() ? landmarkBytes(lm_origin[idx]) : 0);
      if (bytes + kf_bytes + lm_bytes + extra > byte_cap) break;
      if (it == in_packet.end()) {
        add.push_back(idx);
        lm_bytes += extra - 3;
      } else {
        bk.landmarks.push_back(it->second);
      }
      kf_bytes += 3;
    }
    if (bytes + kf_bytes > byte_cap) break;                   // full
    if (bk.landmarks.empty() && add.empty() && !mine.empty()) break;  // not one landmark fits
    // (A keyframe whose landmarks all went already still goes, without any: it
    // is then held and no longer a candidate.)
    for (std::size_t idx : add) {
      const auto at = static_cast<std::uint32_t>(p.landmarks.size());
      in_packet.emplace(idx, at);
      bk.landmarks.push_back(at);
      BorrowedLandmark bl;
      bl.origin = lm_origin[idx];
      bl.p_O = T_O_W * w.landmarks[idx].p_A;
      bl.descriptor = w.landmarks[idx].descriptor;
      p.landmarks.push_back(bl);
    }
    std::sort(bk.landmarks.begin(), bk.landmarks.end());
    bytes += kf_bytes + lm_bytes;
    p.keyframes.push_back(std::move(bk));
  }
  if (p.keyframes.empty()) return std::nullopt;
  return p;
}

}  // namespace server
}  // namespace hermes
