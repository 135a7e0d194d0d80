// The ROS-free edge server pipeline (DESIGN.md §5): one door for frames
// (decode, dedup, bookkeeping via SubmapReceiver), a credibility-ordered queue
// of accepted submaps, and the MapManager that merges them.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>

#include "hermes/core/config.h"
#include "hermes/core/keyring.h"
#include "hermes/core/metrics.h"
#include "hermes/server/admission.h"
#include "hermes/server/bookkeeper.h"
#include "hermes/server/credibility.h"
#include "hermes/server/map_manager.h"
#include "hermes/server/submap_receiver.h"

namespace hermes {
namespace server {

struct ServerParams {
  BookkeeperParams bookkeeper;    ///< server.bookkeeper.*
  CredibilityParams credibility;  ///< server.csa, server.w_ts, ...
  MapManagerParams map;           ///< server.place_recognition.*, server.loop_closure.*, ...
  AuthParams auth;                ///< server.auth.*
  QueueParams queue;              ///< server.queue.*
  Status read(const Config& config, const std::string& prefix = "server.");
  Status validate() const;
  void write(ConfigWriter& out, const std::string& prefix = "server.") const;
};

struct ServerCounters {
  std::size_t merged = 0;
  std::size_t merge_errors = 0;
  std::size_t keyframes_extended = 0;  ///< stored keyframes keyframe extensions added keypoints to
  std::size_t extensions_unknown = 0;  ///< extensions naming a keyframe the map does not hold
  std::size_t loops_reverified = 0;    ///< loops closed again after extensions
  std::string last_error;
};

class Server {
 public:
  /// Loads the vocabulary (relative paths resolved against base_dir) and, with
  /// params.auth.enabled, the keyring: `keyring` when given, else the key
  /// directory params.auth.key_dir ("~/" expanded).
  static Expected<std::unique_ptr<Server>> create(const ServerParams& params,
                                                  const std::string& base_dir,
                                                  std::optional<Keyring> keyring = std::nullopt);
  /// `keyring` is required exactly when params.auth.enabled (checked).
  Server(const ServerParams& params, std::shared_ptr<const Vocabulary> vocabulary,
         std::optional<Keyring> keyring = std::nullopt);
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  /// One received frame (claimed: routing header from the transport, may be null).
  ReceiveResult onFrame(const std::uint8_t* data, std::size_t size, const SubmapHeader* claimed,
                        double now);
  /// Pops up to max_submaps (< 0: all) in credibility order and merges them.
  /// Returns how many were merged.
  int process(double now, int max_submaps = -1);

  std::size_t pending() const { return queue_.size(); }
  const Bookkeeper& bookkeeper() const { return bookkeeper_; }
  const CredibilityAssessor& credibility() const { return queue_; }
  const MapManager& mapManager() const { return map_; }
  MapManager& mapManager() { return map_; }
  const GlobalMap& map() const { return map_.map(); }
  const ReceiverStats& receiverStats() const { return receiver_.stats(); }
  /// What the server holds for a robot awaiting merge (nullptr: nothing ever).
  const HeldLoad* heldLoad(RobotId robot) const { return quotas_.load(robot); }
  const ServerCounters& counters() const { return counters_; }
  /// Map-manager stages plus "submap" (whole merge incl. queue handling) [ms].
  TimingStats timings() const;
  const ServerParams& params() const { return params_; }

 private:
  ServerParams params_;
  std::optional<Keyring> keyring_;
  RobotQuotas quotas_;
  Bookkeeper bookkeeper_;
  CredibilityAssessor queue_;
  MapManager map_;
  SubmapReceiver receiver_;
  std::map<std::uint64_t, ReceivedSubmap> stored_;
  std::uint64_t next_handle_ = 0;
  ServerCounters counters_;
  TimingStats timings_;
};

}  // namespace server
}  // namespace hermes
