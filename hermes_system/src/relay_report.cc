#include "hermes/system/relay_report.h"

#include <algorithm>
#include <cstdio>
#include <sstream>

#include <nlohmann/json.hpp>

namespace hermes::system {

std::optional<RelaySummary> summarizeRelay(const OfflineRun& run) {
  const RelayNetwork* net = run.network();
  if (!net) return std::nullopt;
  RelaySummary s;
  s.scenario = net->scenario().origin;
  s.enabled = run.params().relay.enabled;
  for (const OfflineAgent& a : run.agents())
    s.mission_s = std::max(s.mission_s, a.dataset->frameTime(a.frames - 1) - a.clock_offset);
  const double period = run.params().clock.sample_period_s;
  const std::vector<RobotTraffic> traffic = net->traffic();
  s.exactly_once = true;
  for (std::size_t i = 0; i < run.agents().size(); ++i) {
    const OfflineAgent& a = run.agents()[i];
    RelayRobotReport r;
    r.agent = a.name;
    r.server_link = net->scenario().serverLink(a.name) != nullptr;
    r.own_kBps = s.mission_s > 0 ? traffic[i].own_bytes / s.mission_s / 1000.0 : 0.0;
    r.relayed_kBps = s.mission_s > 0 ? traffic[i].relayed_bytes / s.mission_s / 1000.0 : 0.0;
    r.relayed_submaps = traffic[i].relayed_submaps;
    r.relayed_by = traffic[i].relayed_by;
    r.submitted = a.pipeline->uplink()->stats().submitted;
    if (a.robot)
      if (const AgentStats* st = run.server().bookkeeper().stats(*a.robot)) {
        r.accepted = st->submaps_accepted;
        r.applied = st->submaps_applied;
      }
    r.exactly_once = r.submitted > 0 && r.applied == r.submitted && r.accepted == r.applied &&
                     a.pipeline->uplink()->buffer().pendingCount() == 0;
    s.exactly_once = s.exactly_once && r.exactly_once;
    r.min_relayed_mbitps = net->minRelayedMbitps(period, a.name);
    if (auto e = run.estimates().find(a.name); e != run.estimates().end()) {
      std::vector<double> kBps;
      for (const auto& [t, Bps] : e->second)  // over the mission (not a long drain's decay)
        if (Bps > 0 && t <= s.mission_s) kBps.push_back(Bps / 1000.0);
      if (!kBps.empty()) r.planned_kBps = timing::percentile(kBps, 50);
    }
    s.robots.push_back(r);
  }
  s.min_relayed_mbitps = net->minRelayedMbitps(period);
  return s;
}

nlohmann::json relayJson(const RelaySummary& s) {
  nlohmann::json robots = nlohmann::json::array();
  for (const RelayRobotReport& r : s.robots) {
    nlohmann::json j = {{"agent", r.agent},
                        {"server_link", r.server_link},
                        {"own_kBps", r.own_kBps},
                        {"relayed_kBps", r.relayed_kBps},
                        {"relayed_submaps", r.relayed_submaps},
                        {"relayed_by", r.relayed_by},
                        {"submaps_submitted", r.submitted},
                        {"submaps_accepted", r.accepted},
                        {"submaps_applied", r.applied},
                        {"exactly_once", r.exactly_once}};
    j["min_relayed_mbitps"] = r.min_relayed_mbitps ? nlohmann::json(*r.min_relayed_mbitps) : nlohmann::json();
    j["planned_kBps"] = r.planned_kBps ? nlohmann::json(*r.planned_kBps) : nlohmann::json();
    robots.push_back(j);
  }
  nlohmann::json j = {{"scenario", s.scenario},
                      {"enabled", s.enabled},
                      {"mission_s", s.mission_s},
                      {"robots", robots},
                      {"exactly_once", s.exactly_once}};
  j["min_relayed_mbitps"] = s.min_relayed_mbitps ? nlohmann::json(*s.min_relayed_mbitps) : nlohmann::json();
  return j;
}

std::string formatRelay(const RelaySummary& s) {
  std::ostringstream o;
  char buf[256];
  std::snprintf(buf, sizeof buf, "relay %s (scenario %s): min relayed %s Mbit/s, every submap applied once: %s\n",
                s.enabled ? "on" : "off", s.scenario.c_str(),
                s.min_relayed_mbitps ? std::to_string(*s.min_relayed_mbitps).substr(0, 5).c_str() : "-",
                s.exactly_once ? "yes" : "no");
  o << buf;
  for (const RelayRobotReport& r : s.robots) {
    std::snprintf(buf, sizeof buf,
                  "  %-14s own %7.1f kB/s  relayed for others %7.1f kB/s  planned on %7.1f kB/s  "
                  "via relay %zu submap(s)%s%s  applied %zu/%zu%s\n",
                  r.agent.c_str(), r.own_kBps, r.relayed_kBps, r.planned_kBps.value_or(0.0), r.relayed_submaps,
                  r.relayed_by.empty() ? "" : " by ", r.relayed_by.c_str(), r.applied, r.submitted,
                  r.min_relayed_mbitps
                      ? ("  min " + std::to_string(*r.min_relayed_mbitps).substr(0, 5) + " Mbit/s").c_str()
                      : "");
    o << buf;
  }
  return o.str();
}

}  // namespace hermes::system
