#include "hermes/core/link_trace.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <sstream>

namespace hermes {

LinkTrace LinkTrace::constant(double rate_mbitps, double latency_ms, double loss) {
  LinkTrace t;
  t.unlimited_ = !(rate_mbitps > 0) || std::isinf(rate_mbitps);
  t.rows_.push_back({0.0, {t.unlimited_ ? 1e6 : rate_mbitps, latency_ms, loss}});
  return t;
}

Expected<LinkTrace> LinkTrace::fromString(const std::string& text, const std::string& origin) {
  LinkTrace t;
  std::istringstream in(text);
  std::string line;
  int lineno = 0;
  bool header_seen = false;
  while (std::getline(in, line)) {
    ++lineno;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const auto first = line.find_first_not_of(" \t");
    if (first == std::string::npos || line[first] == '#') continue;
    if (!header_seen) {
      header_seen = true;
      std::string h = line;
      h.erase(std::remove_if(h.begin(), h.end(), ::isspace), h.end());
      if (h != "time_s,rate_mbitps,latency_ms,loss")
        return Error{origin + ":" + std::to_string(lineno) +
                     ": header must be 'time_s,rate_mbitps,latency_ms,loss'"};
      continue;
    }
    std::replace(line.begin(), line.end(), ',', ' ');
    std::istringstream ss(line);
    Row r{};
    std::string extra;
    if (!(ss >> r.time_s >> r.state.rate_mbitps >> r.state.latency_ms >> r.state.loss) ||
        (ss >> extra))
      return Error{origin + ":" + std::to_string(lineno) + ": expected 4 numbers"};
    const auto where = origin + ":" + std::to_string(lineno) + ": ";
    if (!std::isfinite(r.time_s) || r.time_s < 0) return Error{where + "time_s must be >= 0"};
    if (!t.rows_.empty() && r.time_s <= t.rows_.back().time_s)
      return Error{where + "time_s must increase"};
    if (!(r.state.rate_mbitps >= 0) || !std::isfinite(r.state.rate_mbitps))
      return Error{where + "rate_mbitps must be a finite number >= 0"};
    if (!(r.state.latency_ms >= 0) || !std::isfinite(r.state.latency_ms))
      return Error{where + "latency_ms must be >= 0"};
    if (!(r.state.loss >= 0 && r.state.loss <= 1)) return Error{where + "loss must be in [0, 1]"};
    t.rows_.push_back(r);
  }
  if (t.rows_.empty()) return Error{origin + ": link trace has no rows"};
  return t;
}

Expected<LinkTrace> LinkTrace::fromCsv(const std::string& path) {
  std::ifstream in(path);
  if (!in) return Error{"link trace '" + path + "' cannot be opened"};
  std::stringstream ss;
  ss << in.rdbuf();
  return fromString(ss.str(), path);
}

LinkState LinkTrace::at(double t) const {
  const Row* cur = &rows_.front();
  for (const auto& r : rows_) {
    if (r.time_s <= t) cur = &r;
    else break;
  }
  return cur->state;
}

double LinkTrace::nextChange(double t) const {
  for (const auto& r : rows_)
    if (r.time_s > t) return r.time_s;
  return std::numeric_limits<double>::infinity();
}

}  // namespace hermes
