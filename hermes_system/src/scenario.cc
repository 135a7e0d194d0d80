#include "hermes/system/scenario.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace hermes::system {
namespace fs = std::filesystem;

namespace {

std::string joined(const std::vector<std::string>& names) {
  std::string out;
  for (const std::string& n : names) out += (out.empty() ? "" : ", ") + n;
  return out;
}

/// `const:RATE[:LATENCY[:LOSS]]` as a constant trace.
Expected<LinkTrace> constantTrace(const std::string& spec) {
  std::vector<double> v;
  std::stringstream ss(spec.substr(6));
  for (std::string item; std::getline(ss, item, ':');) {
    char* end = nullptr;
    const double x = std::strtod(item.c_str(), &end);
    if (item.empty() || *end != '\0') return Error{"'" + spec + "': '" + item + "' is not a number"};
    v.push_back(x);
  }
  if (v.empty() || v.size() > 3)
    return Error{"'" + spec + "': expected const:RATE_MBITPS[:LATENCY_MS[:LOSS]]"};
  const double rate = v[0], latency = v.size() > 1 ? v[1] : 0.0, loss = v.size() > 2 ? v[2] : 0.0;
  if (!(rate > 0) || !std::isfinite(rate)) return Error{"'" + spec + "': the rate must be > 0 Mbit/s"};
  if (!(latency >= 0) || !std::isfinite(latency)) return Error{"'" + spec + "': latency must be >= 0 ms"};
  if (!(loss >= 0 && loss < 1)) return Error{"'" + spec + "': loss must be in [0, 1)"};
  return LinkTrace::constant(rate, latency, loss);
}

}  // namespace

Expected<Scenario> Scenario::parse(const std::string& text, const std::string& origin,
                                   const std::string& base_dir,
                                   const std::vector<std::string>& robots) {
  Scenario sc;
  sc.origin = origin;
  auto known = [&](const std::string& r) {
    return std::find(robots.begin(), robots.end(), r) != robots.end();
  };
  std::istringstream in(text);
  std::string line;
  for (int lineno = 1; std::getline(in, line); ++lineno) {
    const std::string where = origin + ":" + std::to_string(lineno) + ": ";
    if (const auto hash = line.find('#'); hash != std::string::npos) line.erase(hash);
    std::istringstream words(line);
    std::vector<std::string> w;
    for (std::string x; words >> x;) w.push_back(x);
    if (w.empty()) continue;
    if (w[0] != "link" || w.size() != 4)
      return Error{where + "expected 'link FROM TO TRACE' (TO = server or a robot)"};
    ScenarioLink l;
    l.from = w[1];
    l.to = w[2];
    l.line = lineno;
    if (!known(l.from))
      return Error{where + "unknown robot '" + l.from + "' (robots of this run: " + joined(robots) + ")"};
    if (!l.toServer() && !known(l.to))
      return Error{where + "unknown robot '" + l.to + "' (robots of this run: " + joined(robots) +
                   "; or server)"};
    if (l.from == l.to) return Error{where + "a link from " + l.from + " to itself"};
    for (const ScenarioLink& o : sc.links)
      if (o.from == l.from && o.to == l.to)
        return Error{where + "a second link from " + l.from + " to " + l.to + " (first on line " +
                     std::to_string(o.line) + ")"};
    if (w[3].rfind("const:", 0) == 0) {
      auto t = constantTrace(w[3]);
      if (!t) return Error{where + t.error()};
      l.trace = *t;
    } else {
      fs::path p(w[3]);
      if (p.is_relative()) p = fs::path(base_dir) / p;
      auto t = LinkTrace::fromCsv(p.string());
      if (!t) return Error{where + "trace of " + l.from + " -> " + l.to + ": " + t.error()};
      l.trace = *t;
    }
    sc.links.push_back(std::move(l));
  }
  for (const std::string& r : robots)
    if (!sc.serverLink(r) && sc.robotLinks(r).empty())
      return Error{origin + ": robot " + r + " has no link (add 'link " + r + " server TRACE' or a link to a robot)"};
  for (const ScenarioLink& l : sc.links)
    if (!l.toServer() && !sc.serverLink(l.to))
      return Error{origin + ":" + std::to_string(l.line) + ": " + l.to + " relays for " + l.from +
                   " but has no link to the server itself (relay chains are not supported)"};
  return sc;
}

Expected<Scenario> Scenario::fromFile(const std::string& path, const std::vector<std::string>& robots) {
  std::ifstream in(path);
  if (!in) return Error{"scenario file '" + path + "' cannot be opened"};
  std::stringstream ss;
  ss << in.rdbuf();
  return parse(ss.str(), path, fs::path(path).parent_path().string(), robots);
}

const ScenarioLink* Scenario::serverLink(const std::string& robot) const {
  for (const ScenarioLink& l : links)
    if (l.from == robot && l.toServer()) return &l;
  return nullptr;
}

std::vector<const ScenarioLink*> Scenario::robotLinks(const std::string& robot) const {
  std::vector<const ScenarioLink*> out;
  for (const ScenarioLink& l : links)
    if (l.from == robot && !l.toServer()) out.push_back(&l);
  return out;
}

}  // namespace hermes::system
