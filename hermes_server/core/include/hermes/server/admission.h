// Who may hand the server a frame, and how much one robot may make it hold
// (DESIGN.md §9, server durability and trust; issue 20 items 2 and 3).
//
// Authentication (server.auth.*): with `enabled`, the server loads the key
// directory (keyring.h) at start and the receiver refuses, before anything is
// decoded, a frame of a robot without a key ("unknown_robot"), without a tag
// ("missing_tag") or with a tag that is not its key's ("bad_tag"). A replayed
// frame has a valid tag, so it is refused by (session, seq): acknowledged as
// already applied, never applied twice ("replay").
//
// Fairness (server.queue.*): every robot has its own bound on what the server
// holds for it between arrival and merge: at most `max_per_robot` submaps and
// `max_mbytes_per_robot` of frame bytes. Policy when a new submap would exceed
// either bound: REFUSE it with reason "quota" and no acknowledgement. Nothing is
// dropped: the robot keeps the submap in its spool and resends it after its
// resend timeout, by which time the merger has drained its queue. A robot with
// nothing held always gets one submap in, whatever its size (DecodeLimits bound
// a single frame), so no submap is refused forever. Resends of submaps already
// accepted are acknowledged without touching the quota, and the other robots'
// bounds are untouched by whatever one robot sends: beyond its own bounded
// share of the queue, a flooding or looping robot costs the server a CRC and a
// tag check per frame (no decode). Memory held per robot is reported in the
// metrics (per_agent held_submaps / held_bytes / held_bytes_peak). The merge
// order itself stays the credibility queue's (credibility.h).
#pragma once

#include <cstddef>
#include <map>
#include <string>

#include "hermes/core/config.h"
#include "hermes/core/status.h"
#include "hermes/server/bookkeeper.h"

namespace hermes {

struct AuthParams {
  bool enabled = false;                          ///< refuse frames without a valid tag
  std::string key_dir = "~/.config/hermes/keys"; ///< one <robot>.key per robot
  Status read(const Config& config, const std::string& prefix = "server.auth.");
  void write(ConfigWriter& out, const std::string& prefix = "server.auth.") const;
  Status validate() const;
};

struct QueueParams {
  int max_per_robot = 32;             ///< submaps held per robot awaiting merge [count]
  double max_mbytes_per_robot = 32;   ///< frame bytes held per robot awaiting merge [MB]
  Status read(const Config& config, const std::string& prefix = "server.queue.");
  void write(ConfigWriter& out, const std::string& prefix = "server.queue.") const;
  Status validate() const;
};

/// What the server holds for one robot between arrival and merge.
struct HeldLoad {
  std::size_t submaps = 0, bytes = 0;
  std::size_t peak_submaps = 0, peak_bytes = 0;
  std::size_t refused = 0;  ///< submaps refused for this robot's quota
};

/// Per-robot queue and byte bounds (the policy above). Not thread-safe: owned
/// by the server next to its queue.
class RobotQuotas {
 public:
  explicit RobotQuotas(QueueParams params = {}) : params_(params) {}

  /// Empty when a submap of `bytes` may be held for `robot`, otherwise the
  /// reason it is refused (and the refusal is counted).
  std::string admit(RobotId robot, std::size_t bytes);
  void hold(RobotId robot, std::size_t bytes);
  void release(RobotId robot, std::size_t bytes);
  const HeldLoad* load(RobotId robot) const;
  const QueueParams& params() const { return params_; }

 private:
  QueueParams params_;
  std::map<RobotId, HeldLoad> loads_;
};

}  // namespace hermes
