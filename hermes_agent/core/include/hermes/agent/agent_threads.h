// Threading of one agent (DESIGN §9, agent threads): whether the agent runs its
// stages on worker threads, the uplink stage's queue, and the counters the
// pipeline reports (AgentPipeline::threadStats).
//
//   caller's thread   Tracker::feed        features, tracking, keyframe insertion,
//                                          culling / triangulation / fusion,
//                                          window cut (copies), applies finished BAs
//   mapper thread     local BA             on copies of the window (tracker.h policy)
//   uplink thread     window step          distill, encode, spool, send (queue below)
//
// In synchronous mode (parallel: false, the default: tests and the offline
// runner, deterministic) every stage runs inside feed() exactly as before the
// threads existed.
#pragma once

#include <cstdint>

#include "hermes/agent/stage_worker.h"
#include "hermes/agent/tracker.h"
#include "hermes/core/config.h"

namespace hermes::agent {

struct AgentThreadParams {
  /// Run local BA and the window step on worker threads (agent.parallel).
  bool parallel = false;
  /// Windows waiting for the uplink stage (agent.window_queue). A window cut
  /// while the queue is full is merged into the newest waiting window
  /// (mergeWindows: one submap standing for both periods), never dropped.
  int window_queue = 2;
  /// Stage timings summarised over each stage's last N samples (agent.timing_window);
  /// 0 keeps every sample (offline runs). A live agent summarises every second for
  /// hours: a window bounds memory and the cost of each summary.
  int timing_window = 0;

  /// Keys agent.parallel, agent.window_queue, agent.timing_window (missing keys keep defaults).
  Status read(const Config& config);
  void write(ConfigWriter* writer) const;
  Status validate() const;
};

/// What the threaded stages did (also filled in synchronous mode).
struct AgentThreadStats {
  bool parallel = false;
  std::int64_t frames_fed = 0;      ///< frames feed() accepted
  std::int64_t frames_tracked = 0;  ///< ... with tracking OK
  MappingStageStats mapping;        ///< local mapping stage (tracker.h)
  StageStats windows;               ///< uplink stage: pushed = windows queued (+ retries)
  std::int64_t window_retries = 0;  ///< retries of a carried window queued
};

}  // namespace hermes::agent
