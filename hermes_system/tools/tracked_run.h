// Shared by the whole-sequence benchmarks (bench_system, bench_multisession):
// an offline run whose tracking is replayed from `tracking_dir` where the
// recordings there fit its robots and recorded there otherwise
// (tracking_record.h): the agents' tracking is most of a run's time, and one
// recording per robot serves every run of the same sequence.
// Header-only, like bench_args.h.
#pragma once

#include <cstdio>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "hermes/core/config_file.h"
#include "hermes/system/offline_run.h"
#include "hermes/system/tracking_record.h"

namespace hermes::system::bench {

using Robots = std::vector<std::pair<std::string, std::filesystem::path>>;  // name, dataset folder

/// The defaults plus `sets`, every robot on one shared link of `bw` Mbit/s,
/// spools not synced to disk (a benchmark's runs are not crash-tested).
inline Expected<SystemParams> benchParams(std::vector<std::string> sets, const std::string& bw) {
  sets.push_back("link.bandwidth_mbitps=" + bw);
  sets.push_back("uplink.buffer.fsync=false");
  auto config = loadConfig("", sets);
  if (!config.ok()) return Error{config.error()};
  return readSystemParams(*config);
}

/// One source per robot, opened as `params` reads datasets.
inline Expected<std::vector<AgentSource>> openRobots(const Robots& robots, const SystemParams& params) {
  std::vector<AgentSource> sources;
  for (const auto& [name, dir] : robots) {
    auto ds = Dataset::open(dir.string(), params.run.dataset);
    if (!ds.ok()) return Error{ds.error()};
    sources.push_back({name, std::move(*ds), 0});
  }
  return sources;
}

/// Creates the run of `params` on the sources `open()` gives, spooling under
/// `spool`. With a `tracking_dir`: replay when every recording fits, record
/// otherwise (also when a fitting recording cannot be replayed, e.g. cut
/// short); `*mode` becomes "live", "replay" or "record"; `label` names the run
/// in the messages on stderr.
inline Expected<std::unique_ptr<OfflineRun>> createTrackedRun(
    SystemParams params, const std::function<Expected<std::vector<AgentSource>>()>& open,
    const std::string& tracking_dir, const std::string& spool, const std::string& label, std::string* mode) {
  auto sources = open();
  if (!sources) return Error{sources.error()};
  *mode = "live";
  if (!tracking_dir.empty()) {
    const Status fit = trackingRecordingsFit(params, *sources, tracking_dir);
    *mode = fit ? "replay" : "record";
    params.clock.tracking_replay_dir = tracking_dir;
    if (!fit) params.clock.tracking_record_dir = tracking_dir;
    if (!fit && std::filesystem::exists(tracking_dir))
      std::fprintf(stderr, "  %s: recording the tracking again where it does not fit: %s\n", label.c_str(),
                   fit.error().c_str());
  }
  auto run = OfflineRun::create(params, std::move(*sources), spool, HERMES_SOURCE_DIR);
  if (!run.ok() && *mode == "replay") {  // e.g. a recording cut short: record it again
    std::fprintf(stderr, "  %s: recording the tracking again: %s\n", label.c_str(), run.error().c_str());
    *mode = "record";
    params.clock.tracking_replay_dir.clear();
    params.clock.tracking_record_dir = tracking_dir;
    sources = open();
    if (!sources) return Error{sources.error()};
    run = OfflineRun::create(params, std::move(*sources), spool, HERMES_SOURCE_DIR);
  }
  return run;
}

}  // namespace hermes::system::bench
