#include "hermes/agent/borrowed_map.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <utility>

namespace hermes::agent {

Status BorrowedMapParams::read(const Config& c, const std::string& p) {
  for (auto [key, ptr] : {std::pair<const char*, int*>{"max_landmarks", &max_landmarks},
                          {"max_hamming", &max_hamming},
                          {"min_inliers", &min_inliers}}) {
    Status s = c.get(p + "." + key, ptr);
    if (!s) return s;
  }
  for (auto [key, ptr] : {std::pair<const char*, double*>{"ratio", &ratio},
                          {"search_radius_m", &search_radius_m}}) {
    Status s = c.get(p + "." + key, ptr);
    if (!s) return s;
  }
  return validate();
}

void BorrowedMapParams::write(ConfigWriter* w, const std::string& p) const {
  w->set(p + ".max_landmarks", max_landmarks);
  w->set(p + ".max_hamming", max_hamming);
  w->set(p + ".ratio", ratio);
  w->set(p + ".min_inliers", min_inliers);
  w->set(p + ".search_radius_m", search_radius_m);
}

Status BorrowedMapParams::validate() const {
  if (max_landmarks < 1) return Error{"borrowed.max_landmarks must be >= 1"};
  if (max_hamming < 0 || max_hamming > 256) return Error{"borrowed.max_hamming must be in [0, 256]"};
  if (!(ratio > 0 && ratio <= 1)) return Error{"borrowed.ratio must be in (0, 1]"};
  if (min_inliers < 4) return Error{"borrowed.min_inliers must be >= 4"};
  if (!(search_radius_m >= 0) || !std::isfinite(search_radius_m))
    return Error{"borrowed.search_radius_m must be finite and >= 0"};
  if (!(octave_scale >= 1) || !std::isfinite(octave_scale))
    return Error{"borrowed.octave_scale must be finite and >= 1"};
  return Status::Ok();
}

namespace {

constexpr std::uint32_t kDropped = std::numeric_limits<std::uint32_t>::max();
constexpr int kNoDistance = 257;  // above any Hamming distance of 256-bit descriptors

/// Typical heap cost of one std::map / std::set node beyond its value: the
/// red-black tree header (colour, parent, left, right) and the allocator's
/// bookkeeping on a 64-bit glibc.
constexpr std::size_t kNodeOverhead = 32 + 16;
constexpr std::size_t kAllocOverhead = 16;

template <class V>
std::size_t vectorBytes(const std::vector<V>& v) {
  return v.capacity() == 0 ? 0 : v.capacity() * sizeof(V) + kAllocOverhead;
}

std::string describe(const Vec3& p) {
  char buf[96];
  std::snprintf(buf, sizeof(buf), "(%.2f, %.2f, %.2f)", p.x(), p.y(), p.z());
  return buf;
}

}  // namespace

void BorrowedMap::TakenSeqs::add(std::uint64_t seq) {
  if (seq != contiguous + 1) {
    above.insert(seq);
    return;
  }
  ++contiguous;
  while (!above.empty() && *above.begin() == contiguous + 1) {
    above.erase(above.begin());
    ++contiguous;
  }
}

BorrowedMap::BorrowedMap(const BorrowedMapParams& params) : params_(params) {
  const Status s = params_.validate();
  HERMES_CHECK(s.ok(), s.error());
}

IngestResult BorrowedMap::ingest(const MapDownPacket& packet, const Uuid& self, std::string* why) {
  const auto refuse = [&](std::string reason) {
    ++refused_;
    if (why) *why = std::move(reason);
    return IngestResult::kRefused;
  };
  const std::string name = "map_down packet (epoch " + std::to_string(packet.epoch) + ", seq " +
                           std::to_string(packet.seq) + ")";
  if (packet.agent != self)
    return refuse(name + " is for robot " + toString(packet.agent) + ", this is " +
                  toString(self));
  const Status valid = packet.validate();
  if (!valid) return refuse(name + ": " + valid.error());

  TakenSeqs& taken = taken_[packet.epoch];
  if (taken.has(packet.seq)) {
    ++duplicates_;
    return IngestResult::kDuplicate;
  }
  taken.add(packet.seq);
  ++packets_taken_;

  const SE3& T_W_O = packet.T_W_O;
  // Landmarks first: the keyframes name them by their index in the packet.
  std::vector<std::uint32_t> index(packet.landmarks.size());
  Vec3 centre = Vec3::Zero();
  for (std::size_t i = 0; i < packet.landmarks.size(); ++i) {
    const BorrowedLandmark& l = packet.landmarks[i];
    const Vec3 p_W = T_W_O * l.p_O;
    centre += p_W;
    const auto [it, inserted] =
        lm_index_.try_emplace(l.origin, static_cast<std::uint32_t>(lm_p_W_.size()));
    index[i] = it->second;
    if (inserted) {
      lm_p_W_.push_back(p_W);
      lm_desc_.push_back(l.descriptor);
      lm_key_.push_back(l.origin);
    } else {  // the newer copy replaces the one held
      lm_p_W_[it->second] = p_W;
      lm_desc_[it->second] = l.descriptor;
    }
  }
  if (!packet.landmarks.empty()) centre /= double(packet.landmarks.size());

  Vec3 camera_sum = Vec3::Zero();
  for (const BorrowedKeyframe& kf : packet.keyframes) {
    HeldKeyframe held;
    held.stamp = kf.stamp;
    held.T_W_C = T_W_O * kf.T_O_C;
    camera_sum += held.T_W_C.translation();
    held.landmarks.reserve(kf.landmarks.size());
    for (std::uint32_t i : kf.landmarks) held.landmarks.push_back(index[i]);
    if (held.landmarks.empty()) {  // nothing to match through it: not kept
      keyframes_.erase(kf.origin);
      continue;
    }
    keyframes_.insert_or_assign(kf.origin, std::move(held));
  }
  if (!packet.keyframes.empty()) centre = camera_sum / double(packet.keyframes.size());

  enforceBound(centre);
  return IngestResult::kTaken;
}

void BorrowedMap::enforceBound(const Vec3& centre_W) {
  const std::size_t n = lm_p_W_.size();
  const std::size_t cap = static_cast<std::size_t>(params_.max_landmarks);
  if (n <= cap) return;
  const Vec3 c = robot_p_W_ ? *robot_p_W_ : centre_W;

  // The cap nearest landmarks stay; the rest go.
  std::vector<std::pair<double, std::uint32_t>> by_distance(n);
  for (std::size_t i = 0; i < n; ++i)
    by_distance[i] = {(lm_p_W_[i] - c).squaredNorm(), static_cast<std::uint32_t>(i)};
  std::nth_element(by_distance.begin(), by_distance.begin() + cap, by_distance.end());
  std::vector<std::uint32_t> remap(n, kDropped);
  for (std::size_t k = 0; k < cap; ++k) remap[by_distance[k].second] = 0;

  // Compact the arrays in their order; remap[old] = new index or kDropped.
  std::uint32_t next = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (remap[i] == kDropped) continue;
    remap[i] = next;
    if (next != i) {
      lm_p_W_[next] = lm_p_W_[i];
      lm_desc_[next] = lm_desc_[i];
      lm_key_[next] = lm_key_[i];
    }
    ++next;
  }
  lm_p_W_.resize(cap);
  lm_desc_.resize(cap);
  lm_key_.resize(cap);
  for (auto it = lm_index_.begin(); it != lm_index_.end();) {
    const std::uint32_t j = remap[it->second];
    if (j == kDropped) {
      it = lm_index_.erase(it);
    } else {
      it->second = j;
      ++it;
    }
  }
  evicted_landmarks_ += n - cap;

  for (auto it = keyframes_.begin(); it != keyframes_.end();) {
    std::vector<std::uint32_t>& seen = it->second.landmarks;
    std::size_t kept = 0;
    for (std::uint32_t old : seen)
      if (remap[old] != kDropped) seen[kept++] = remap[old];
    seen.resize(kept);
    if (seen.empty()) {
      it = keyframes_.erase(it);
      ++evicted_keyframes_;
    } else {
      ++it;
    }
  }
}

std::vector<std::uint32_t> BorrowedMap::candidates(const std::optional<Vec3>& guess_W) const {
  std::vector<std::uint32_t> out;
  if (!(params_.search_radius_m > 0) || !guess_W) {
    out.resize(lm_p_W_.size());
    for (std::size_t i = 0; i < out.size(); ++i) out[i] = static_cast<std::uint32_t>(i);
    return out;
  }
  const double r2 = params_.search_radius_m * params_.search_radius_m;
  std::vector<bool> taken(lm_p_W_.size(), false);
  for (const auto& [key, kf] : keyframes_) {
    if ((kf.T_W_C.translation() - *guess_W).squaredNorm() > r2) continue;
    for (std::uint32_t i : kf.landmarks) {
      if (taken[i]) continue;
      taken[i] = true;
      out.push_back(i);
    }
  }
  std::sort(out.begin(), out.end());  // read the descriptors in memory order
  return out;
}

Expected<BorrowedMap::Relocalisation> BorrowedMap::relocalise(
    const std::vector<Keypoint>& keypoints, const std::vector<Descriptor>& descriptors,
    const PinholeIntrinsics& K, double baseline, const PoseEstimationParams& pose,
    const std::optional<Vec3>& guess_W) const {
  if (keypoints.size() != descriptors.size())
    return Error{"relocalisation: " + std::to_string(keypoints.size()) + " keypoints but " +
                 std::to_string(descriptors.size()) + " descriptors"};
  if (lm_p_W_.empty()) return Error{"relocalisation: the borrowed map is empty"};
  const std::vector<std::uint32_t> cand = candidates(guess_W);
  if (cand.empty())
    return Error{"relocalisation: no borrowed keyframe within " +
                 std::to_string(params_.search_radius_m) + " m of the guess " +
                 describe(*guess_W)};

  // Each keypoint's best candidate (threshold, ratio test); a candidate keeps
  // the keypoint closest to it.
  std::vector<int> best_keypoint(cand.size(), -1);
  std::vector<int> best_distance(cand.size(), kNoDistance);
  for (std::size_t k = 0; k < keypoints.size(); ++k) {
    const Descriptor& q = descriptors[k];
    int d1 = kNoDistance, d2 = kNoDistance;
    std::size_t j1 = 0;
    for (std::size_t j = 0; j < cand.size(); ++j) {
      const int d = hammingDistance(q, lm_desc_[cand[j]]);
      if (d < d1) {
        d2 = d1;
        d1 = d;
        j1 = j;
      } else if (d < d2) {
        d2 = d;
      }
    }
    if (d1 > params_.max_hamming) continue;
    if (d2 != kNoDistance && !(d1 < params_.ratio * d2)) continue;
    if (d1 < best_distance[j1]) {
      best_distance[j1] = d1;
      best_keypoint[j1] = static_cast<int>(k);
    }
  }

  Correspondences c;
  const bool stereo = baseline > 0;
  if (stereo) c.baseline = baseline;
  for (std::size_t j = 0; j < cand.size(); ++j) {
    if (best_keypoint[j] < 0) continue;
    const Keypoint& kp = keypoints[best_keypoint[j]];
    c.p_W.push_back(lm_p_W_[cand[j]]);
    c.uv.emplace_back(kp.u, kp.v);
    c.sigma_px.push_back(std::pow(params_.octave_scale, kp.octave));
    if (stereo) c.u_right.push_back(K.rightColumn(kp.u, kp.depth, baseline));
  }
  const int matches = static_cast<int>(c.size());
  const int need = std::max(params_.min_inliers, pose.min_inliers);
  const std::string counts = std::to_string(matches) + " descriptor matches of " +
                             std::to_string(keypoints.size()) + " keypoints to " +
                             std::to_string(cand.size()) + " borrowed landmarks";
  if (matches < need)
    return Error{"relocalisation: " + counts + ", need " + std::to_string(need)};

  PoseEstimationParams pp = pose;
  pp.min_inliers = need;
  Expected<PoseEstimate> est = estimatePose(c, K, pp);
  if (!est) return Error{"relocalisation (" + counts + "): " + est.error()};
  if (est->num_inliers < need)
    return Error{"relocalisation (" + counts + "): " + std::to_string(est->num_inliers) +
                 " inliers, need " + std::to_string(need)};
  Relocalisation r;
  r.T_W_C = est->T_C_W.inverse();
  r.inliers = est->num_inliers;
  r.matches = matches;
  r.rms_px = est->rms_px;
  return r;
}

std::optional<Vec3> BorrowedMap::landmark(const KeyframeKey& origin) const {
  const auto it = lm_index_.find(origin);
  if (it == lm_index_.end()) return std::nullopt;
  return lm_p_W_[it->second];
}

std::optional<SE3> BorrowedMap::keyframePose(const KeyframeKey& origin) const {
  const auto it = keyframes_.find(origin);
  if (it == keyframes_.end()) return std::nullopt;
  return it->second.T_W_C;
}

std::size_t BorrowedMap::memoryBytes() const {
  std::size_t bytes = sizeof(*this) + vectorBytes(lm_p_W_) + vectorBytes(lm_desc_) +
                      vectorBytes(lm_key_);
  bytes += lm_index_.size() *
           (kNodeOverhead + sizeof(std::pair<const KeyframeKey, std::uint32_t>));
  bytes += keyframes_.size() *
           (kNodeOverhead + sizeof(std::pair<const KeyframeKey, HeldKeyframe>));
  for (const auto& [key, kf] : keyframes_) bytes += vectorBytes(kf.landmarks);
  bytes += taken_.size() * (kNodeOverhead + sizeof(std::pair<const std::uint64_t, TakenSeqs>));
  for (const auto& [epoch, t] : taken_)
    bytes += t.above.size() * (kNodeOverhead + sizeof(std::uint64_t));
  return bytes;
}

}  // namespace hermes::agent
