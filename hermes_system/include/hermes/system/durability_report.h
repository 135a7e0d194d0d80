// What a run's server checkpoints and restarts did (metrics.json
// "server_durability" and "server_restarts"; present when the server had a
// checkpoint directory).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "hermes/system/offline_run.h"

namespace hermes::system {

struct DurabilitySummary {
  std::string checkpoint_dir;
  server::DurabilityStats server;       ///< accumulated over every server of the run
  std::vector<ServerRestart> restarts;
  std::size_t submaps_resent = 0;       ///< frames the agents handed to the link again
  std::size_t duplicates_dropped = 0;   ///< frames the server only acknowledged again
  std::size_t frames_lost_down = 0;     ///< frames that arrived while the server was down
  std::size_t submaps_accepted = 0;     ///< over all agents (bookkeeper)
  std::size_t submaps_applied = 0;      ///< over all agents (bookkeeper): each at most once
};

/// Nothing when the run's server had no checkpoint directory.
std::optional<DurabilitySummary> summarizeDurability(const OfflineRun& run);
nlohmann::json durabilityJson(const DurabilitySummary& d);
/// One line for the report.
std::string formatDurability(const DurabilitySummary& d);

}  // namespace hermes::system
