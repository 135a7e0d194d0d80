// The server's durable state on disk (DESIGN.md §9), one directory:
//
//   DIR/checkpoint-<n>.hck    whole server state after a merge (n = 1, 2, ...;
//                             the newest `keep` are kept, older ones deleted)
//   DIR/queue/<uuid>-<session>-<seq>.hjf
//                             journal: every accepted submap's frame, written
//                             (and fsynced) before it is acknowledged, deleted
//                             once a checkpoint covers it
//   *.refused                 a checkpoint or journal file that could not be
//                             read, renamed so it is kept for inspection and
//                             never tried again
//
// Checkpoint file: "HCKP", u32 format version, u64 body length, body (the
// server's state, server_checkpoint.cc), CRC-32 of everything before it.
// Journal file: "HJNL", u32 format version, f64 arrival time [s], u64 frame
// length, the frame as received, CRC-32 of everything before it.
// Every file is written to a temporary name, fsynced, renamed into place and
// the directory fsynced: a crash leaves the previous file or the new one,
// never a mixture.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "hermes/core/config.h"
#include "hermes/core/map_types.h"
#include "hermes/core/status.h"

namespace hermes {
namespace server {

/// 2: per-session anchoring and re-localisation state (bookkeeper).
/// 3: global map version 3 inside (loop keypoint pairs, refined edges).
/// 4: the loop closures deferred by server.map.closure_budget.
constexpr std::uint32_t kCheckpointVersion = 4;
constexpr std::uint32_t kJournalVersion = 1;

struct CheckpointParams {
  std::string dir;        ///< server.checkpoint_dir; empty = no checkpoints, nothing resumed
  double period_s = 0;    ///< server.checkpoint_period_s: at most this often (0 = after every merge) [s]
  int keep = 2;           ///< server.checkpoint_keep: newest checkpoints kept (>= 2)
  /// server.prior_map: a directory holding a checkpoint of an earlier mission
  /// (its newest usable one is read, nothing in it is changed): the server
  /// starts on that map, in its world frame, unless `dir` already holds a
  /// checkpoint of this mission (which holds the prior too). Empty = none.
  std::string prior_map;
  /// server.prior_map_optional: a prior map that cannot be read is a warning
  /// and the server starts empty, instead of an error.
  bool prior_map_optional = false;
  bool enabled() const { return !dir.empty(); }
  Status read(const Config& config, const std::string& prefix = "server.");
  void write(ConfigWriter& out, const std::string& prefix = "server.") const;
  Status validate() const;
};

/// Writes `bytes` to `path` atomically (temporary file, fsync, rename, fsync of
/// the directory). Errors name the file.
Status writeFileAtomically(const std::string& path, const std::vector<std::uint8_t>& bytes);

/// A journal entry: an accepted submap's frame as it arrived.
struct JournalEntry {
  std::string file;
  double arrival = 0;
  std::vector<std::uint8_t> frame;
};

class CheckpointStore {
 public:
  /// Creates DIR and DIR/queue when missing and removes temporary files a
  /// crash left behind.
  static Expected<CheckpointStore> open(const CheckpointParams& params);

  /// Writes the next checkpoint and deletes the ones beyond `keep`. Returns its path.
  Expected<std::string> write(const std::vector<std::uint8_t>& body);
  /// Checkpoint files, newest first.
  std::vector<std::string> checkpoints() const { return listCheckpoints(params_.dir); }
  /// The checkpoint files of any directory, newest first (nothing is changed).
  static std::vector<std::string> listCheckpoints(const std::string& dir);
  /// The body of a checkpoint file after checking magic, version, length and
  /// CRC; the error says what is wrong (the caller names the file).
  static Expected<std::vector<std::uint8_t>> readCheckpoint(const std::string& path);
  /// Renames a file that could not be used to <file>.refused.
  static void refuse(const std::string& path);

  Status journalPut(const SubmapHeader& routing, double arrival, const std::uint8_t* frame,
                    std::size_t size);
  void journalRemove(const SubmapHeader& routing);
  /// Every journal entry in arrival order; unreadable ones are refused and
  /// their reasons appended to `problems`.
  std::vector<JournalEntry> journal(std::vector<std::string>* problems) const;

  const CheckpointParams& params() const { return params_; }

 private:
  explicit CheckpointStore(CheckpointParams params) : params_(std::move(params)) {}
  std::string journalPath(const SubmapHeader& routing) const;

  CheckpointParams params_;
  std::uint64_t next_ = 1;  ///< number of the next checkpoint file
};

}  // namespace server
}  // namespace hermes
