#include "hermes/system/system_params.h"

#include <cmath>
#include <iomanip>
#include <sstream>

namespace hermes::system {

Status LinkParams::read(const Config& c) {
  for (Status s : {c.get("link.bandwidth_mbitps", &bandwidth_mbitps),
                   c.get("link.latency_ms", &latency_ms), c.get("link.loss", &loss),
                   c.get("link.trace", &trace), c.get("link.scenario", &scenario),
                   c.get("link.packet_bytes", &packet_bytes),
                   c.get("link.seed", &seed)})
    if (!s) return s;
  return validate();
}

Status LinkParams::validate() const {
  if (!(bandwidth_mbitps >= 0) || !std::isfinite(bandwidth_mbitps))
    return Error{"link.bandwidth_mbitps must be >= 0 (0 = unlimited)"};
  if (!(latency_ms >= 0) || !std::isfinite(latency_ms)) return Error{"link.latency_ms must be >= 0"};
  if (!(loss >= 0 && loss < 1)) return Error{"link.loss must be in [0, 1)"};
  if (packet_bytes < 64) return Error{"link.packet_bytes must be >= 64"};
  return Status::Ok();
}

void LinkParams::write(ConfigWriter& w) const {
  w.set("link.bandwidth_mbitps", bandwidth_mbitps);
  w.set("link.latency_ms", latency_ms);
  w.set("link.loss", loss);
  w.set("link.trace", trace);
  w.set("link.scenario", scenario);
  w.set("link.packet_bytes", packet_bytes);
  w.set("link.seed", seed);
}

Expected<LinkTrace> LinkParams::makeTrace() const {
  if (!trace.empty()) {
    auto t = LinkTrace::fromCsv(trace);
    if (!t.ok()) return Error{"link.trace: " + t.error()};
    return *t;
  }
  return LinkTrace::constant(bandwidth_mbitps, latency_ms, loss);
}

Expected<std::vector<AgentReset>> parseAgentResets(const std::string& spec) {
  std::vector<AgentReset> out;
  const auto trim = [](std::string v) {
    const auto b = v.find_first_not_of(" \t");
    const auto e = v.find_last_not_of(" \t");
    return b == std::string::npos ? std::string() : v.substr(b, e - b + 1);
  };
  if (trim(spec).empty()) return out;
  std::size_t start = 0;
  while (start <= spec.size()) {
    const std::size_t comma = std::min(spec.find(',', start), spec.size());
    const std::string item = trim(spec.substr(start, comma - start));
    const std::size_t at = item.rfind('@');
    const std::string bad = "agent reset '" + item + "' is not NAME@S (S: simulated seconds >= 0)";
    if (at == std::string::npos || at == 0 || at + 1 == item.size()) return Error{bad};
    AgentReset r;
    r.agent = trim(item.substr(0, at));
    const std::string time = trim(item.substr(at + 1));
    std::size_t used = 0;
    try {
      r.at_s = std::stod(time, &used);
    } catch (const std::exception&) {
      return Error{bad};
    }
    if (used != time.size() || r.agent.empty() || !std::isfinite(r.at_s) || r.at_s < 0)
      return Error{bad};
    out.push_back(r);
    start = comma + 1;
  }
  return out;
}

std::string formatAgentResets(const std::vector<AgentReset>& resets) {
  std::string out;
  for (const AgentReset& r : resets) {
    std::ostringstream item;
    item << r.agent << "@" << std::setprecision(17) << r.at_s;
    out += (out.empty() ? "" : ", ") + item.str();
  }
  return out;
}

Status ClockParams::read(const Config& c) {
  std::string resets = formatAgentResets(agent_reset);
  if (Status s = c.get("system.agent_reset", &resets); !s) return s;
  auto parsed = parseAgentResets(resets);
  if (!parsed) return Error{"system.agent_reset: " + parsed.error()};
  agent_reset = std::move(*parsed);
  for (Status s : {c.get("system.step_s", &step_s), c.get("system.server_period_s", &server_period_s),
                   c.get("system.sample_period_s", &sample_period_s),
                   c.get("system.drain_s", &drain_s),
                   c.get("system.health_period_s", &health_period_s),
                   c.get("system.agent_threads", &agent_threads),
                   c.get("system.server_restart_at", &server_restart_at),
                   c.get("system.server_downtime_s", &server_downtime_s),
                   c.get("system.tracking_record_dir", &tracking_record_dir),
                   c.get("system.tracking_replay_dir", &tracking_replay_dir)})
    if (!s) return s;
  return validate();
}

Status ClockParams::validate() const {
  if (!(step_s > 0 && step_s <= 0.1)) return Error{"system.step_s must be in (0, 0.1] s"};
  if (!(server_period_s >= step_s)) return Error{"system.server_period_s must be >= system.step_s"};
  if (!(sample_period_s >= step_s)) return Error{"system.sample_period_s must be >= system.step_s"};
  if (!(drain_s >= 0) || !std::isfinite(drain_s)) return Error{"system.drain_s must be >= 0"};
  if (!(health_period_s >= 0) || !std::isfinite(health_period_s))
    return Error{"system.health_period_s must be >= 0 (0 = no health samples)"};
  if (agent_threads < 1 || agent_threads > 64)
    return Error{"system.agent_threads must be in [1, 64], got " + std::to_string(agent_threads)};
  for (double t : server_restart_at)
    if (!(t >= 0) || !std::isfinite(t))
      return Error{"system.server_restart_at: every time must be >= 0 s, got " + std::to_string(t)};
  if (!(server_downtime_s >= 0) || !std::isfinite(server_downtime_s))
    return Error{"system.server_downtime_s must be >= 0"};
  for (const AgentReset& r : agent_reset)
    if (r.agent.empty() || !(r.at_s >= 0) || !std::isfinite(r.at_s))
      return Error{"system.agent_reset: '" + formatAgentResets({r}) +
                   "' needs an agent name and a time >= 0 s"};
  if ((!tracking_record_dir.empty() || !tracking_replay_dir.empty()) && !agent_reset.empty())
    return Error{"system.tracking_record_dir / tracking_replay_dir: not with system.agent_reset "
                 "(a reset tracks a fresh map)"};
  return Status::Ok();
}

void ClockParams::write(ConfigWriter& w) const {
  w.set("system.step_s", step_s);
  w.set("system.server_period_s", server_period_s);
  w.set("system.sample_period_s", sample_period_s);
  w.set("system.drain_s", drain_s);
  w.set("system.health_period_s", health_period_s);
  w.set("system.agent_threads", agent_threads);
  w.set("system.server_restart_at", server_restart_at);
  w.set("system.server_downtime_s", server_downtime_s);
  w.set("system.agent_reset", formatAgentResets(agent_reset));
  w.set("system.tracking_record_dir", tracking_record_dir);
  w.set("system.tracking_replay_dir", tracking_replay_dir);
}

Status SystemParams::read(const Config& config) {
  if (Status s = run.read(config); !s) return s;
  if (Status s = server.read(config, "server."); !s) return Error{"server: " + s.error()};
  if (Status s = link.read(config); !s) return s;
  if (Status s = relay.read(config); !s) return s;
  if (Status s = clock.read(config); !s) return s;
  if (Status s = corrupt.read(config); !s) return s;
  if (Status s = transport.read(config); !s) return s;
  return validate();
}

Status SystemParams::validate() const {
  for (Status s : {run.validate(), server.validate(), link.validate(), relay.validate(), clock.validate(),
                   corrupt.validate(), transport.validate()})
    if (!s) return s;
  // Both read server.credibility.w_ts / w_mc; only code can set them apart.
  if (relay.w_ts != server.credibility.w_ts || relay.w_mc != server.credibility.w_mc)
    return Error{"the relay's credibility weights (relay.w_ts / w_mc in code) differ from "
                 "server.credibility.w_ts / w_mc, the one key for both"};
  if (run.agent.uplink.auth.enabled != server.auth.enabled)
    return Error{std::string("uplink.auth.enabled (the robots tag their frames) is ") +
                 (run.agent.uplink.auth.enabled ? "true" : "false") + " but server.auth.enabled is " +
                 (server.auth.enabled ? "true" : "false") + ": set both to the same value"};
  return Status::Ok();
}

void SystemParams::write(ConfigWriter& w) const {
  run.write(&w);
  server.write(w, "server.");
  link.write(w);
  relay.write(w);
  clock.write(w);
  corrupt.write(&w);
  transport.write(w);
}

std::string SystemParams::yaml() const {
  ConfigWriter w;
  write(w);
  return w.yaml();
}

agent::AgentPipelineParams SystemParams::offlineAgent() const {
  agent::AgentPipelineParams ap = run.agent;
  if (ap.distill.solver_limits == "auto") ap.distill.solver_limits = "work";
  return ap;
}

Expected<SystemParams> readSystemParams(const Config& config) {
  SystemParams params;
  if (Status s = params.read(config); !s) return Error{s.error() + " (in " + config.origin() + ")"};
  if (Status s = agent::rejectUnreadKeys(config); !s) return Error{s.error()};
  return params;
}

}  // namespace hermes::system
