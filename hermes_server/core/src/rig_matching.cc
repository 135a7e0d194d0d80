#include "hermes/server/rig_matching.h"

#include <algorithm>
#include <cstring>
#include <limits>

namespace hermes {
namespace server {

namespace {

using Packed = std::array<std::uint64_t, 4>;

std::vector<Packed> pack(const std::vector<Descriptor>& descriptors) {
  std::vector<Packed> out(descriptors.size());
  for (std::size_t i = 0; i < descriptors.size(); ++i) {
    std::memcpy(out[i].data(), descriptors[i].data(), sizeof(Packed));
  }
  return out;
}

inline int hamming(const Packed& a, const Packed& b) {
  return __builtin_popcountll(a[0] ^ b[0]) + __builtin_popcountll(a[1] ^ b[1]) +
         __builtin_popcountll(a[2] ^ b[2]) + __builtin_popcountll(a[3] ^ b[3]);
}

constexpr int kInf = std::numeric_limits<int>::max();

/// Brute force between two cameras: per row of `a` its best and second-best
/// distance (and best index), per column of `b` its best row. Cloned for POPCNT
/// (baseline x86-64 builds would call libgcc's table popcount instead).
#if defined(__x86_64__) && defined(__GNUC__)
__attribute__((target_clones("popcnt", "default")))
#endif
void bestTwo(const std::vector<Packed>& a, const std::vector<Packed>& b, std::vector<int>* best,
             std::vector<int>* second, std::vector<int>* best_idx, std::vector<int>* col_best,
             std::vector<int>* col_idx) {
  best->assign(a.size(), kInf);
  second->assign(a.size(), kInf);
  best_idx->assign(a.size(), -1);
  col_best->assign(b.size(), kInf);
  col_idx->assign(b.size(), -1);
  for (std::size_t p = 0; p < a.size(); ++p) {
    int b1 = kInf, b2 = kInf, i1 = -1;
    for (std::size_t q = 0; q < b.size(); ++q) {
      const int d = hamming(a[p], b[q]);
      if (d < b1) {
        b2 = b1;
        b1 = d;
        i1 = static_cast<int>(q);
      } else if (d < b2) {
        b2 = d;
      }
      if (d < (*col_best)[q]) {
        (*col_best)[q] = d;
        (*col_idx)[q] = static_cast<int>(p);
      }
    }
    (*best)[p] = b1;
    (*second)[p] = b2;
    (*best_idx)[p] = i1;
  }
}

Status checkKeyframe(const Keyframe& kf, const std::vector<PinholeIntrinsics>& cameras) {
  const std::string where = "keyframe " + std::to_string(kf.id);
  if (kf.camera_id >= cameras.size()) {
    return Error{where + ": camera_id " + std::to_string(kf.camera_id) + " but only " +
                 std::to_string(cameras.size()) + " cameras"};
  }
  const PinholeIntrinsics& cam = cameras[kf.camera_id];
  if (!(cam.fx > 0) || !(cam.fy > 0)) return Error{where + ": camera has non-positive focal length"};
  if (kf.descriptors.size() != kf.keypoints.size()) {
    return Error{where + ": " + std::to_string(kf.descriptors.size()) + " descriptors for " +
                 std::to_string(kf.keypoints.size()) + " keypoints"};
  }
  if (!kf.T_A_C.translation().allFinite() || !kf.T_A_C.quat().coeffs().allFinite()) {
    return Error{where + ": non-finite pose T_A_C"};
  }
  return Status::Ok();
}

}  // namespace

Expected<Rig> makeRig(const Keyframe& reference, const std::vector<const Keyframe*>& neighbours,
                      const std::vector<PinholeIntrinsics>& cameras) {
  Rig rig;
  std::vector<const Keyframe*> all{&reference};
  for (const Keyframe* kf : neighbours) {
    if (kf == nullptr) return Error{"makeRig: null neighbour keyframe"};
    all.push_back(kf);
  }
  const SE3 T_ref_A = reference.T_A_C.inverse();
  for (const Keyframe* kf : all) {
    Status s = checkKeyframe(*kf, cameras);
    if (!s) return Error{"makeRig: " + s.error()};
    rig.keyframes.push_back(kf);
    rig.intrinsics.push_back(cameras[kf->camera_id]);
    rig.T_ref_C.push_back(T_ref_A * kf->T_A_C);
  }
  return rig;
}

Status RigMatchingParams::read(const Config& config, const std::string& prefix) {
  for (Status s : {config.get(prefix + ".max_hamming", &max_hamming),
                   config.get(prefix + ".ratio", &ratio),
                   config.get(prefix + ".cross_check", &cross_check),
                   config.get(prefix + ".max_matches_per_keypoint", &max_matches_per_keypoint)}) {
    if (!s) return s;
  }
  return validate();
}

void RigMatchingParams::write(ConfigWriter* writer, const std::string& prefix) const {
  writer->set(prefix + ".max_hamming", max_hamming);
  writer->set(prefix + ".ratio", ratio);
  writer->set(prefix + ".cross_check", cross_check);
  writer->set(prefix + ".max_matches_per_keypoint", max_matches_per_keypoint);
}

Status RigMatchingParams::validate() const {
  if (max_hamming < 1 || max_hamming > 256) return Error{"rig matching: max_hamming must be in [1, 256]"};
  if (!(ratio > 0.0 && ratio <= 1.0)) return Error{"rig matching: ratio must be in (0, 1]"};
  if (max_matches_per_keypoint < 1) return Error{"rig matching: max_matches_per_keypoint must be >= 1"};
  return Status::Ok();
}

std::vector<RigMatch> matchRigs(const Rig& query, const Rig& candidate,
                                const RigMatchingParams& params) {
  std::vector<std::vector<Packed>> dq, dc;
  for (const Keyframe* kf : query.keyframes) dq.push_back(pack(kf->descriptors));
  for (const Keyframe* kf : candidate.keyframes) dc.push_back(pack(kf->descriptors));

  // Per query keypoint, matches found in each candidate camera.
  std::vector<std::vector<std::vector<RigMatch>>> per_kp(dq.size());
  for (std::size_t i = 0; i < dq.size(); ++i) per_kp[i].resize(dq[i].size());

  for (std::size_t i = 0; i < dq.size(); ++i) {
    for (std::size_t j = 0; j < dc.size(); ++j) {
      const auto& a = dq[i];
      const auto& b = dc[j];
      if (a.empty() || b.empty()) continue;
      std::vector<int> best, second, best_idx, col_best, col_idx;
      bestTwo(a, b, &best, &second, &best_idx, &col_best, &col_idx);
      for (std::size_t p = 0; p < a.size(); ++p) {
        if (best_idx[p] < 0 || best[p] > params.max_hamming) continue;
        if (second[p] != kInf && best[p] >= params.ratio * second[p]) continue;
        if (params.cross_check && col_idx[best_idx[p]] != static_cast<int>(p)) continue;
        per_kp[i][p].push_back(RigMatch{static_cast<int>(i), static_cast<int>(p),
                                        static_cast<int>(j), best_idx[p], best[p]});
      }
    }
  }

  std::vector<RigMatch> out;
  for (auto& cam : per_kp) {
    for (auto& list : cam) {
      std::sort(list.begin(), list.end(),
                [](const RigMatch& x, const RigMatch& y) { return x.distance < y.distance; });
      const std::size_t n = std::min<std::size_t>(list.size(), params.max_matches_per_keypoint);
      out.insert(out.end(), list.begin(), list.begin() + n);
    }
  }
  return out;
}

}  // namespace server
}  // namespace hermes
