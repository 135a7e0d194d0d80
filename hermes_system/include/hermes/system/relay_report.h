// What relaying did in a scenario run (metrics.json "relay"; present when the
// run had link.scenario): per robot the rate of its own submaps on its first
// hop and of the submaps it forwarded for others, which relays carried its
// submaps, whether each submap it made was applied exactly once, and the
// lowest rate a relayed robot got while it was relayed.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "hermes/system/offline_run.h"

namespace hermes::system {

struct RelayRobotReport {
  std::string agent;
  bool server_link = false;       ///< the scenario gives it a link to the server
  double own_kBps = 0;            ///< its own submaps on its first hop, over the mission
  double relayed_kBps = 0;        ///< other robots' submaps it forwarded, over the mission
  std::size_t relayed_submaps = 0;  ///< of its own, acknowledged through a relay
  std::string relayed_by;         ///< those relays
  std::size_t submitted = 0, accepted = 0, applied = 0;  ///< its uplink / the server's bookkeeper
  bool exactly_once = false;      ///< every submap it made applied once, its spool drained
  std::optional<double> min_relayed_mbitps;  ///< while relayed (RelayNetwork::minRelayedMbitps)
  /// Median of its monitor's non-zero estimates over the mission [kB/s]: the rate
  /// its coordinator planned with (for a relayed robot: of its link to the relay).
  std::optional<double> planned_kBps;
};

struct RelaySummary {
  std::string scenario;
  bool enabled = false;           ///< relay.enabled
  double mission_s = 0;           ///< [s] last frame over all robots (the kB/s divide by it)
  std::vector<RelayRobotReport> robots;
  std::optional<double> min_relayed_mbitps;  ///< over every relayed robot
  bool exactly_once = false;      ///< for every robot
};

/// Nothing without a scenario.
std::optional<RelaySummary> summarizeRelay(const OfflineRun& run);
nlohmann::json relayJson(const RelaySummary& r);
std::string formatRelay(const RelaySummary& r);

}  // namespace hermes::system
