// Helpers shared by the map manager's source files (map_manager.cc: the merge
// pipeline; one file per stage: _store, _loops, _anchoring, _optimize, _io).
#pragma once

#include <chrono>

#include "hermes/core/stopwatch.h"
#include "hermes/server/global_map.h"

namespace hermes {
namespace server {
namespace map_manager_detail {

using Clock = std::chrono::steady_clock;
using hermes::msSince;

inline KeyframeKey keyOf(const TrajectoryMap& t, KeyframeId id) { return KeyframeKey{t.agent, t.session, id}; }

}  // namespace map_manager_detail
}  // namespace server
}  // namespace hermes
