// The offline runner's side of tracking record / replay (issue 18;
// agent/tracking_log.h): which file holds an agent's recording, the key of
// what determined its tracking, and hooking a pipeline up to record or replay
// as system.tracking_record_dir / tracking_replay_dir say (per agent when
// both are set).
#pragma once

#include <cstddef>
#include <string>

#include "hermes/agent/agent_pipeline.h"
#include "hermes/agent/tracking_log.h"
#include "hermes/core/dataset.h"
#include "hermes/system/offline_run.h"
#include "hermes/system/system_params.h"

namespace hermes::system {

/// DIR/<agent>.htrk
std::string trackingRecordPath(const std::string& dir, const std::string& agent);

/// What the agent's tracking depends on in this run: agent name, dataset folder,
/// frames fed and their first / last stamp, camera, dataset.* and tracker
/// params (hashes of their YAML), this agent's odometry corruption.
agent::TrackingKey trackingKey(const SystemParams& params, const std::string& agent,
                               const Dataset& dataset, std::size_t frames);

/// How an agent's tracking runs: neither dir set: live; record dir only:
/// recorded; replay dir only: replayed; both: replayed when the agent's
/// recording in the replay dir fits this run, else tracked live and recorded
/// into the record dir (one robot of a recorded set re-tracked, e.g. corrupted).
enum class TrackingMode { kLive, kRecord, kReplay };
TrackingMode trackingMode(const SystemParams& params, const std::string& agent,
                          const Dataset& dataset, std::size_t frames);

/// Record mode: `pipeline` records into DIR/<agent>.htrk (the folder is
/// created). Replay mode: it replays that file, refused when its key differs
/// from this run's (the error names the field) or the file is damaged. Live:
/// nothing.
Status setUpTrackingRecord(const SystemParams& params, const std::string& agent,
                           const Dataset& dataset, std::size_t frames,
                           agent::AgentPipeline* pipeline);

/// Ok when every agent of `sources` has a recording in `dir` whose key fits
/// this run (the key alone is read); otherwise the first reason it does not.
Status trackingRecordingsFit(const SystemParams& params, const std::vector<AgentSource>& sources,
                             const std::string& dir);

}  // namespace hermes::system
