#include "hermes/system/durability_report.h"

#include <algorithm>
#include <cstdio>

#include <nlohmann/json.hpp>

namespace hermes::system {

std::optional<DurabilitySummary> summarizeDurability(const OfflineRun& run) {
  const server::Server& srv = run.server();
  if (!srv.params().checkpoint.enabled()) return std::nullopt;
  DurabilitySummary d;
  d.checkpoint_dir = srv.params().checkpoint.dir;
  d.server = srv.durability();
  d.restarts = run.restarts();
  for (const OfflineAgent& a : run.agents()) {
    d.submaps_resent += a.resent;
    d.duplicates_dropped += a.duplicates;
  }
  for (const ServerRestart& r : d.restarts) d.frames_lost_down += r.frames_lost_down;
  for (RobotId r : srv.bookkeeper().robots())
    if (const AgentStats* s = srv.bookkeeper().stats(r)) {
      d.submaps_accepted += s->submaps_accepted;
      d.submaps_applied += s->submaps_applied;
    }
  return d;
}

nlohmann::json durabilityJson(const DurabilitySummary& d) {
  nlohmann::json restarts = nlohmann::json::array();
  for (const ServerRestart& r : d.restarts)
    restarts.push_back({{"down_at_s", r.down_at_s},
                        {"up_at_s", r.up_at_s},
                        {"resume_ms", r.resume_ms},
                        {"resumed_from", r.checkpoint},
                        {"journal_replayed", r.journal_replayed},
                        {"frames_lost_while_down", r.frames_lost_down},
                        {"first_accept_after_s", r.first_accept_s >= 0 ? r.first_accept_s - r.up_at_s : -1.0},
                        {"problems", r.problems}});
  nlohmann::json j;
  j["server_durability"] = {{"checkpoint_dir", d.checkpoint_dir},
                            {"checkpoints", d.server.checkpoints},
                            {"checkpoint_errors", d.server.checkpoint_errors},
                            {"last_checkpoint_bytes", d.server.last_checkpoint_bytes},
                            {"journal_errors", d.server.journal_errors},
                            {"refused_files", d.server.refused_files},
                            {"submaps_accepted", d.submaps_accepted},
                            {"submaps_applied", d.submaps_applied}};
  j["server_restarts"] = {{"count", d.restarts.size()},
                          {"submaps_resent", d.submaps_resent},
                          {"duplicates_dropped", d.duplicates_dropped},
                          {"frames_lost_while_down", d.frames_lost_down},
                          {"journal_replayed", d.server.journal_replayed},
                          {"restarts", restarts}};
  return j;
}

std::string formatDurability(const DurabilitySummary& d) {
  char buf[320];
  double resume_ms = 0;
  for (const ServerRestart& r : d.restarts) resume_ms = std::max(resume_ms, r.resume_ms);
  std::snprintf(buf, sizeof buf,
                "server: %zu checkpoints (last %.1f MB), %zu restarts (resume <= %.0f ms), "
                "%zu submaps resent, %zu duplicates dropped, applied %zu of %zu accepted\n",
                d.server.checkpoints, double(d.server.last_checkpoint_bytes) / 1e6,
                d.restarts.size(), resume_ms, d.submaps_resent, d.duplicates_dropped,
                d.submaps_applied, d.submaps_accepted);
  return buf;
}

}  // namespace hermes::system
