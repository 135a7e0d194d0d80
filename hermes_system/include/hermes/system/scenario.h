// A scenario file (config key link.scenario): who reaches whom over time, one
// link per line, for the offline runner's relay runs.
//
//   # comment
//   link FROM TO TRACE
//
// FROM is a robot of the run (its dataset folder name), TO is `server` or
// another robot; data flows FROM -> TO, acknowledgements come back over the
// same link. TRACE is a link trace CSV (link_trace.h: rate 0 = out of reach;
// a relative path is taken from the scenario file's folder) or
// `const:RATE_MBITPS[:LATENCY_MS[:LOSS]]`. Rules: every robot has at least one
// link; at most one link per (FROM, TO); a robot that others reach
// (a relay) has a link to the server itself (no chains). A robot without a
// server link, or whose server link is down, hands its submaps to a robot it
// reaches (relay.enabled), otherwise they wait. Errors name the file and line.
#pragma once

#include <string>
#include <vector>

#include "hermes/core/link_trace.h"
#include "hermes/core/status.h"

namespace hermes::system {

struct ScenarioLink {
  std::string from, to;  ///< to: "server" or a robot
  LinkTrace trace;
  int line = 0;          ///< in the scenario file
  bool toServer() const { return to == "server"; }
};

struct Scenario {
  std::string origin;               ///< the file it came from
  std::vector<ScenarioLink> links;  ///< in file order

  /// Parses `text` (named `origin` in errors; relative trace paths from
  /// `base_dir`) against the run's robot names.
  static Expected<Scenario> parse(const std::string& text, const std::string& origin,
                                  const std::string& base_dir,
                                  const std::vector<std::string>& robots);
  static Expected<Scenario> fromFile(const std::string& path, const std::vector<std::string>& robots);

  /// The robot's link to the server, or nullptr.
  const ScenarioLink* serverLink(const std::string& robot) const;
  /// The robot's links to other robots, in file order.
  std::vector<const ScenarioLink*> robotLinks(const std::string& robot) const;
};

}  // namespace hermes::system
