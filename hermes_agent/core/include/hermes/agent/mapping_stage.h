// The agent's local-mapping stage (DESIGN §9 agent threads): on every new
// keyframe, local mapping (local_mapper.h: culling, triangulation, fusion,
// windowed bundle adjustment), either inside the caller's step (synchronous,
// the default: bit-identical runs) or with the bundle adjustment on a mapper
// thread so that tracking never waits for it (parallel).
//
// Parallel: culling, triangulation and fusion still run on insertion (they
// change ids the tracker uses; they are short); the BA window is cut as a job
// of copies (LocalMapper::cutBa), solved on the mapper thread, and written back
// by poll() on the caller's thread at the start of a later frame
// (LocalMapper::applyBa: a short critical section, so the map has a single
// writer and needs no lock). Keyframes and landmarks created while a BA runs
// are kept and follow the newest adjusted keyframe's correction, which poll()
// returns so the tracker's motion model can follow it too.
// Queue and drop policy (bounded: at most one BA job waits or runs):
// keyframes are never dropped; keyframes inserted while a BA runs wait and are
// merged into the next job, which adjusts the newest mapping.ba_window
// keyframes: waiting keyframes older than that window get no BA of their own
// (counted as skipped). mappedKeyframes() is the consistent point a window may
// end at: every keyframe before it was adjusted (or skipped) once.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <vector>

#include "hermes/agent/local_mapper.h"
#include "hermes/agent/stage_worker.h"
#include "hermes/core/map_types.h"

namespace hermes {

/// Counters of the local mapping stage (see the policy above).
struct MappingStageStats {
  std::int64_t keyframes = 0;   ///< keyframes inserted after the first
  std::int64_t ba_jobs = 0;     ///< local BAs run (parallel: every job applied, solved or not)
  std::int64_t merged = 0;      ///< keyframes whose BA was merged into a later job
  std::int64_t skipped = 0;     ///< keyframes left out of every BA window (mapper behind)
  std::int64_t max_waiting = 0; ///< most keyframes waiting for a BA at once
  double ba_ms_total = 0, ba_ms_max = 0;  ///< solve times (on the mapper thread if parallel) [ms]
  /// Parallel: culling, triangulation and fusion, which stay on the caller's thread [ms].
  double structure_ms_total = 0, structure_ms_max = 0;
};

/// The map the stage works on: the tracker's keyframes and landmarks (ids are indices).
struct LocalMapRef {
  std::vector<Keyframe>* keyframes;
  std::vector<Landmark>* landmarks;
};

class MappingStage {
 public:
  MappingStage(const LocalMapperParams& params, const PinholeIntrinsics& K, double baseline);
  ~MappingStage();
  MappingStage(const MappingStage&) = delete;
  MappingStage& operator=(const MappingStage&) = delete;

  /// The BA on a mapper thread (true) or inside insert() (false). Set before the
  /// first keyframe. `before_solve` (test hook, may be empty) runs on the mapper
  /// thread before every solve.
  void setParallel(bool parallel, std::function<void()> before_solve = {});
  bool parallel() const { return worker_ != nullptr; }

  /// The map's first keyframe (nothing to map yet): it counts as mapped.
  void startMap(std::size_t keyframes) { mapped_keyframes_ = keyframes; }
  /// Local mapping for the newest keyframe of `map`: all of it (synchronous), or
  /// the structure now and the BA scheduled (parallel; total_ms is then the
  /// structure's time).
  LocalMappingStats insert(LocalMapRef map, const std::vector<float>& scales);
  /// Parallel: applies a finished BA, then starts the next one when keyframes
  /// wait and the mapper is free. Returns the correction W <- W of the newest
  /// adjusted keyframe when a solve was written back. Synchronous: nothing.
  std::optional<SE3> poll(LocalMapRef map);
  /// A BA job is running or keyframes wait for one (parallel only).
  bool busy() const { return worker_ && (in_flight_ || waiting_keyframes_ > 0); }
  /// Blocks until the mapper thread is idle (then poll() applies its result).
  void waitIdle();
  /// Keyframes [0, n) a window may hand out: all of `keyframes` in synchronous
  /// mode, those up to the newest adjusted one in parallel mode.
  std::size_t mappedKeyframes(std::size_t keyframes) const;
  /// A new map: the mapper's per-landmark state and the waiting count start
  /// again (call when not busy()); the counters go on.
  void reset();

  const MappingStageStats& stats() const { return stats_; }
  /// The mapper's per-landmark bookkeeping (culling statistics, bad landmarks).
  LocalMapper& mapper() { return mapper_; }
  const LocalMapper& mapper() const { return mapper_; }

 private:
  void schedule(LocalMapRef map);

  LocalMapperParams params_;
  PinholeIntrinsics K_;
  double baseline_;
  LocalMapper mapper_;
  MappingStageStats stats_;
  std::function<void()> before_solve_;
  std::vector<float> scales_;          ///< pyramid scales for the BA jobs
  std::size_t mapped_keyframes_ = 0;   ///< keyframes [0, n) adjusted or skipped
  int waiting_keyframes_ = 0;          ///< inserted, no BA job cut yet
  bool in_flight_ = false;             ///< a job was pushed and not yet applied
  // The finished-job mailbox, filled by the mapper thread under done_mu_;
  // everything else is touched by the caller's thread only.
  std::mutex done_mu_;
  std::optional<LocalBaJob> done_;
  std::unique_ptr<agent::StageWorker<LocalBaJob>> worker_;  ///< last: joined first
};

}  // namespace hermes
