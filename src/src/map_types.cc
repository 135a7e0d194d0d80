#include "hermes/core/map_types.h"

#include <cstring>
#include <functional>
#include <cstdio>
#include <random>
#include <sstream>
#include <unordered_map>
#include <unordered_set>

namespace hermes {

std::string toString(const Uuid& id) {
  static const char* kHex = "0123456789abcdef";
  std::string s;
  for (std::size_t i = 0; i < id.size(); ++i) {
    if (i == 4 || i == 6 || i == 8 || i == 10) s += '-';
    s += kHex[id[i] >> 4];
    s += kHex[id[i] & 15];
  }
  return s;
}

bool parseUuid(const std::string& text, Uuid* out) {
  Uuid id{};
  std::size_t n = 0;
  for (char c : text) {
    if (c == '-') continue;
    int v;
    if (c >= '0' && c <= '9') v = c - '0';
    else if (c >= 'a' && c <= 'f') v = c - 'a' + 10;
    else if (c >= 'A' && c <= 'F') v = c - 'A' + 10;
    else return false;
    if (n >= 32) return false;
    id[n / 2] = static_cast<std::uint8_t>(id[n / 2] | (n % 2 == 0 ? v << 4 : v));
    ++n;
  }
  if (n != 32) return false;
  *out = id;
  return true;
}

Uuid uuidFromSeed(std::uint64_t seed) {
  std::mt19937_64 rng(seed ^ 0x9e3779b97f4a7c15ULL);
  Uuid id{};
  for (auto& b : id) b = static_cast<std::uint8_t>(rng() & 0xff);
  return id;
}

Uuid agentUuid(const std::string& name) { return uuidFromSeed(std::hash<std::string>{}(name)); }

// Debian builds for baseline x86-64, which has no POPCNT instruction: without a
// clone __builtin_popcountll becomes a libgcc table loop (7 % of a whole run).
#if defined(__x86_64__) && defined(__GNUC__)
__attribute__((target_clones("popcnt", "default")))
#endif
int hammingDistance(const Descriptor& a, const Descriptor& b) {
  int d = 0;
  for (std::size_t i = 0; i < a.size(); i += 8) {
    std::uint64_t x, y;
    std::memcpy(&x, a.data() + i, 8);
    std::memcpy(&y, b.data() + i, 8);
    d += __builtin_popcountll(x ^ y);
  }
  return d;
}

std::size_t Submap::observationCount() const {
  std::size_t n = 0;
  for (const auto& l : landmarks) n += l.observations.size();
  return n;
}

std::size_t Submap::windowKeyframeCount() const {
  std::size_t n = 0;
  for (const Keyframe& kf : keyframes) n += isExtension(kf) ? 0 : 1;
  return n;
}

std::string Submap::validate() const {
  std::ostringstream err;
  std::unordered_map<KeyframeId, const Keyframe*> kfs;
  for (std::size_t i = 0; i < keyframes.size(); ++i) {
    const Keyframe& kf = keyframes[i];
    if (kf.id == kInvalidId) {
      err << "keyframe #" << i << " has an invalid id";
      return err.str();
    }
    if (!kfs.emplace(kf.id, &kf).second) {
      err << "keyframe id " << kf.id << " appears twice";
      return err.str();
    }
    if (kf.camera_id >= cameras.size()) {
      err << "keyframe " << kf.id << " uses camera " << kf.camera_id << " but the submap has "
          << cameras.size() << " cameras";
      return err.str();
    }
    if (kf.descriptors.size() != kf.keypoints.size() ||
        kf.keypoint_landmark.size() != kf.keypoints.size()) {
      err << "keyframe " << kf.id << " has " << kf.keypoints.size() << " keypoints but "
          << kf.descriptors.size() << " descriptors and " << kf.keypoint_landmark.size()
          << " landmark links";
      return err.str();
    }
    if (isExtension(kf)) {
      for (LandmarkId id : kf.keypoint_landmark) {
        if (id != kInvalidId) {
          err << "keyframe extension " << kf.id << " (stamp before the window start) links landmark "
              << id << "; extensions carry keypoints only";
          return err.str();
        }
      }
    }
  }
  std::unordered_set<LandmarkId> lms;
  for (const auto& lm : landmarks) {
    if (lm.id == kInvalidId || !lms.insert(lm.id).second) {
      err << "landmark id " << lm.id << " is invalid or appears twice";
      return err.str();
    }
    if (!lm.p_A.allFinite()) {
      err << "landmark " << lm.id << " has a non-finite position";
      return err.str();
    }
    for (const auto& ob : lm.observations) {
      auto it = kfs.find(ob.keyframe);
      if (it == kfs.end()) {
        err << "landmark " << lm.id << " is observed by unknown keyframe " << ob.keyframe;
        return err.str();
      }
      if (isExtension(*it->second)) {
        err << "landmark " << lm.id << " is observed by keyframe extension " << ob.keyframe;
        return err.str();
      }
      if (ob.keypoint >= it->second->keypoints.size()) {
        err << "landmark " << lm.id << " points at keypoint " << ob.keypoint << " of keyframe "
            << ob.keyframe << " which has " << it->second->keypoints.size();
        return err.str();
      }
    }
  }
  for (const auto& e : odometry) {
    if (!kfs.count(e.from) || !kfs.count(e.to)) {
      err << "odometry edge " << e.from << "->" << e.to << " names a keyframe not in the submap";
      return err.str();
    }
    if (isExtension(*kfs.at(e.from)) || isExtension(*kfs.at(e.to))) {
      err << "odometry edge " << e.from << "->" << e.to << " names a keyframe extension";
      return err.str();
    }
  }
  return {};
}

}  // namespace hermes
