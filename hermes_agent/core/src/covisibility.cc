#include "hermes/agent/covisibility.h"

#include <algorithm>
#include <unordered_map>

namespace hermes {

std::vector<std::pair<KeyframeId, int>> covisibleKeyframes(
    const std::vector<Keyframe>& keyframes, const std::vector<Landmark>& landmarks,
    KeyframeId keyframe, int min_shared) {
  std::unordered_map<KeyframeId, int> count;
  if (keyframe >= keyframes.size()) return {};
  for (LandmarkId id : keyframes[keyframe].keypoint_landmark) {
    if (id == kInvalidId || id >= landmarks.size()) continue;
    KeyframeId last = kInvalidId;  // one vote per landmark and keyframe
    for (const Observation& o : landmarks[id].observations)
      if (o.keyframe != keyframe && o.keyframe != last) {
        ++count[o.keyframe];
        last = o.keyframe;
      }
  }
  std::vector<std::pair<KeyframeId, int>> out;
  for (const auto& [k, n] : count)
    if (n >= min_shared) out.emplace_back(k, n);
  std::sort(out.begin(), out.end(), [](const auto& a, const auto& b) {
    return a.second != b.second ? a.second > b.second : a.first > b.first;
  });
  return out;
}

int sharedLandmarks(const std::vector<Keyframe>& keyframes, const std::vector<Landmark>& landmarks,
                    KeyframeId a, KeyframeId b) {
  if (a >= keyframes.size() || b >= keyframes.size()) return 0;
  int n = 0;
  for (LandmarkId id : keyframes[a].keypoint_landmark) {
    if (id == kInvalidId || id >= landmarks.size()) continue;
    for (const Observation& o : landmarks[id].observations)
      if (o.keyframe == b) {
        ++n;
        break;
      }
  }
  return n;
}

}  // namespace hermes
