// Wall time since a steady-clock instant, in milliseconds: what the stage
// timings (metrics timings_ms) and the benchmarks measure with.
#pragma once

#include <chrono>

namespace hermes {

inline double msSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace hermes
