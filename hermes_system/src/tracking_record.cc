#include "hermes/system/tracking_record.h"

#include <algorithm>
#include <cstdio>
#include <filesystem>

namespace hermes::system {
namespace fs = std::filesystem;
namespace {

std::string exact(double v) {
  char buf[40];
  std::snprintf(buf, sizeof(buf), "%.17g", v);
  return buf;
}

}  // namespace

std::string trackingRecordPath(const std::string& dir, const std::string& agent) {
  return (fs::path(dir) / (agent + ".htrk")).string();
}

agent::TrackingKey trackingKey(const SystemParams& params, const std::string& agent,
                               const Dataset& dataset, std::size_t frames) {
  const DatasetInfo& info = dataset.info();
  agent::TrackingKey key;
  key.add("agent", agent);
  std::error_code ec;
  const fs::path root = fs::weakly_canonical(info.root, ec);
  key.add("dataset", ec ? info.root : root.string());
  key.add("frames", std::to_string(frames));
  key.add("first_stamp", exact(dataset.frameTime(0)));
  key.add("last_stamp", exact(dataset.frameTime(frames - 1)));
  std::string camera;
  for (double v : {info.K.fx, info.K.fy, info.K.cx, info.K.cy, double(info.K.width),
                   double(info.K.height), info.baseline})
    camera += exact(v) + " ";
  const SE3& T = info.T_B_C;
  for (double v : {T.quat().w(), T.quat().x(), T.quat().y(), T.quat().z(), T.translation().x(),
                   T.translation().y(), T.translation().z()})
    camera += exact(v) + " ";
  key.add("camera", agent::textHash(camera));
  ConfigWriter dataset_yaml;
  params.run.dataset.write(dataset_yaml);
  key.add("dataset_params", agent::textHash(dataset_yaml.yaml()));
  ConfigWriter tracker_yaml;
  params.run.agent.tracker.write(&tracker_yaml);
  key.add("tracker_params", agent::textHash(tracker_yaml.yaml()));
  std::string corruption = "none";
  if (params.corrupt.active() && params.corrupt.agent == agent) {
    ConfigWriter corrupt_yaml;
    params.corrupt.write(&corrupt_yaml);
    corruption = agent::textHash(corrupt_yaml.yaml());
  }
  key.add("corruption", corruption);
  return key;
}

TrackingMode trackingMode(const SystemParams& params, const std::string& agent,
                          const Dataset& dataset, std::size_t frames) {
  const ClockParams& c = params.clock;
  if (c.tracking_replay_dir.empty())
    return c.tracking_record_dir.empty() ? TrackingMode::kLive : TrackingMode::kRecord;
  if (c.tracking_record_dir.empty()) return TrackingMode::kReplay;
  auto key = agent::readTrackingKey(trackingRecordPath(c.tracking_replay_dir, agent));
  const bool fits = key && key->matches(trackingKey(params, agent, dataset, frames));
  return fits ? TrackingMode::kReplay : TrackingMode::kRecord;
}

Status setUpTrackingRecord(const SystemParams& params, const std::string& agent,
                           const Dataset& dataset, std::size_t frames,
                           agent::AgentPipeline* pipeline) {
  const ClockParams& c = params.clock;
  const TrackingMode mode = trackingMode(params, agent, dataset, frames);
  if (mode == TrackingMode::kLive) return Status::Ok();
  const agent::TrackingKey key = trackingKey(params, agent, dataset, frames);
  if (mode == TrackingMode::kRecord) {
    std::error_code ec;
    fs::create_directories(c.tracking_record_dir, ec);
    if (ec)
      return Error{"system.tracking_record_dir: cannot create " + c.tracking_record_dir + ": " +
                   ec.message()};
    auto writer = agent::TrackingLogWriter::create(trackingRecordPath(c.tracking_record_dir, agent), key);
    if (!writer) return Error{"agent " + agent + ": " + writer.error()};
    return pipeline->recordTracking(std::move(*writer));
  }
  const std::string path = trackingRecordPath(c.tracking_replay_dir, agent);
  auto log = agent::readTrackingLog(path);
  if (!log) return Error{"agent " + agent + ": " + log.error()};
  if (Status s = log->key.matches(key); !s)
    return Error{"agent " + agent + ": tracking recording " + path +
                 " was made for another run: " + s.error()};
  return pipeline->replayTracking(std::move(*log));
}

Status trackingRecordingsFit(const SystemParams& params, const std::vector<AgentSource>& sources,
                             const std::string& dir) {
  for (const AgentSource& src : sources) {
    if (!src.dataset) return Error{"agent " + src.name + ": no dataset"};
    const std::size_t all = src.dataset->info().frame_count;
    const std::size_t frames = src.max_frames > 0 ? std::min(src.max_frames, all) : all;
    const std::string path = trackingRecordPath(dir, src.name);
    auto key = agent::readTrackingKey(path);
    if (!key) return Error{key.error()};
    if (Status s = key->matches(trackingKey(params, src.name, *src.dataset, frames)); !s)
      return Error{path + ": " + s.error()};
  }
  return Status::Ok();
}

}  // namespace hermes::system
