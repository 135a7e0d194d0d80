// Recording of an agent's tracking (issue 18): everything the window step and
// the runner's metrics take from the tracker, so that a later run can replay it
// instead of tracking the images again. Tracking does not depend on the link,
// the server or the distiller, so one recording serves every variant and
// bandwidth of the same sequence.
//
// One file per agent, written as the run goes (TrackingLogWriter) and read
// whole (readTrackingLog). Lossless: doubles and floats are stored bit for bit
// (the wire format would round landmarks to floats). Layout, little-endian:
//
//   "HTRK" magic, u16 version (kTrackingLogVersion)
//   records: u8 type, u32 payload bytes, payload, u32 CRC-32 over type..payload
//     kKey      (first)  the TrackingKey: u32 n, n x (text name, text value)
//     kStep     (one per fed frame, then one for flushWindow) a TrackingStep
//     kSummary  (last)   the TrackingSummary; a file without it is refused
//   text = u32 bytes + bytes; counts are u64 and never trusted beyond the bytes left.
//
// The key names what determined the tracking (dataset, frames, tracker
// params, corruption); replaying under another key is refused naming the field.
#pragma once

#include <cstdint>
#include <fstream>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "hermes/agent/tracker.h"
#include "hermes/core/map_types.h"
#include "hermes/core/status.h"
#include "hermes/distill/scores.h"

namespace hermes::agent {

constexpr std::uint16_t kTrackingLogVersion = 1;

/// What determined the tracking, as (field, value) pairs in a fixed order.
struct TrackingKey {
  std::vector<std::pair<std::string, std::string>> fields;

  void add(const std::string& name, const std::string& value) { fields.emplace_back(name, value); }
  /// Ok when equal; otherwise an error naming the first differing field with
  /// the recorded and the expected value (`this` is the recorded key).
  Status matches(const TrackingKey& expected) const;
};

/// A short stable hash of a text (FNV-1a 64, hex): params YAML in the key.
std::string textHash(const std::string& text);

/// One step of the tracker: a fed frame, or the end-of-sequence flush.
struct TrackingStep {
  bool flush = false;            ///< flushWindow's step (no frame)
  double stamp = 0;              ///< [s] frame stamp; flush: the stamp the window was cut at
  TrackingStatus status = TrackingStatus::kNotInitialised;  ///< frames only
  SE3 T_W_B;                     ///< odometry body pose, corruption applied (status kOk)
  distill::MotionHint motion;    ///< tracker's hint after this step's window cut
  std::optional<Submap> window;  ///< window handed out at this step (window hook applied)
};

/// The tracker's totals at the end (AgentPipeline::metrics()).
struct TrackingSummary {
  std::int64_t frames = 0, lost = 0;
  std::int64_t keyframes = 0, landmarks = 0;
  distill::TrackingHealth total_health;
};

struct TrackingLog {
  TrackingKey key;
  std::vector<TrackingStep> steps;
  TrackingSummary summary;
};

/// Appends the records as the run goes; close() writes the summary.
class TrackingLogWriter {
 public:
  /// Creates (truncates) `path` and writes the magic, version and key.
  static Expected<std::unique_ptr<TrackingLogWriter>> create(const std::string& path,
                                                             const TrackingKey& key);
  Status append(const TrackingStep& step);
  /// Writes the summary and closes the file (a file without it is refused).
  Status close(const TrackingSummary& summary);
  const std::string& path() const { return path_; }

 private:
  TrackingLogWriter(std::string path, std::ofstream out) : path_(std::move(path)), out_(std::move(out)) {}
  Status writeRecord(std::uint8_t type, const std::vector<std::uint8_t>& payload);
  std::string path_;
  std::ofstream out_;
};

/// Moves every stamp of `log` by `dt_s` (steps, their windows' spans and
/// keyframes): a recording replayed later on a mission's clock (a robot flying
/// the same sequence again, mission.h). The key is left as recorded.
void shiftTrackingLog(TrackingLog* log, double dt_s);

/// The whole file's bytes (tests) / file contents decoded. Errors name the file,
/// the record and the byte offset (truncated, CRC mismatch, bad value).
Expected<TrackingLog> decodeTrackingLog(const std::vector<std::uint8_t>& bytes,
                                        const std::string& what);
Expected<TrackingLog> readTrackingLog(const std::string& path);
/// Only the key at the start of the file (cheap: whether a recording fits a run).
Expected<TrackingKey> readTrackingKey(const std::string& path);

/// Lossless Submap bytes (the record payload format; exposed for tests).
void encodeSubmapLossless(const Submap& submap, std::vector<std::uint8_t>* out);

}  // namespace hermes::agent
