// Covisibility between keyframes: the number of landmarks two keyframes share,
// computed from the landmark observation lists (always consistent with fusion
// and culling, no separate graph state to keep in sync).
#pragma once

#include <utility>
#include <vector>

#include "hermes/core/map_types.h"

namespace hermes {

/// Keyframes sharing at least `min_shared` landmarks with `keyframe`, as
/// (keyframe id, shared count), most shared first. Keyframe ids index `keyframes`.
std::vector<std::pair<KeyframeId, int>> covisibleKeyframes(
    const std::vector<Keyframe>& keyframes, const std::vector<Landmark>& landmarks,
    KeyframeId keyframe, int min_shared);

/// Number of landmarks seen by both keyframes.
int sharedLandmarks(const std::vector<Keyframe>& keyframes, const std::vector<Landmark>& landmarks,
                    KeyframeId a, KeyframeId b);

}  // namespace hermes
