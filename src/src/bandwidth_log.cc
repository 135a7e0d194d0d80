#include "hermes/core/bandwidth_log.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <sstream>

namespace hermes {

Status writeBandwidthCsv(const std::string& path, const std::vector<BandwidthSample>& samples) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (!f) return Error{"cannot write bandwidth file '" + path + "'"};
  std::fprintf(f, "time_s,agent,kBps,link_capacity_kBps\n");
  for (const BandwidthSample& s : samples) {
    if (s.agent.find_first_of(",\n\r") != std::string::npos) {
      std::fclose(f);
      return Error{"bandwidth file '" + path + "': agent name '" + s.agent +
                   "' contains a comma or newline"};
    }
    std::fprintf(f, "%.6f,%s,%.6f,", s.time_s, s.agent.c_str(), s.kBps);
    if (s.link_capacity_kBps) std::fprintf(f, "%.6f", *s.link_capacity_kBps);
    std::fprintf(f, "\n");
  }
  if (std::fclose(f) != 0) return Error{"error while writing bandwidth file '" + path + "'"};
  return Status::Ok();
}

namespace {

bool parseDouble(const std::string& text, double* out) {
  if (text.empty()) return false;
  char* end = nullptr;
  *out = std::strtod(text.c_str(), &end);
  return end == text.c_str() + text.size() && std::isfinite(*out);
}

std::string trim(const std::string& s) {
  const auto a = s.find_first_not_of(" \t\r");
  if (a == std::string::npos) return "";
  return s.substr(a, s.find_last_not_of(" \t\r") - a + 1);
}

}  // namespace

Expected<std::vector<BandwidthSample>> readBandwidthCsv(const std::string& path) {
  std::ifstream in(path);
  if (!in) return Error{"bandwidth file '" + path + "' cannot be opened"};
  std::string line;
  if (!std::getline(in, line) || trim(line) != "time_s,agent,kBps,link_capacity_kBps")
    return Error{path + ":1: header must be 'time_s,agent,kBps,link_capacity_kBps'"};
  std::vector<BandwidthSample> out;
  int lineno = 1;
  while (std::getline(in, line)) {
    ++lineno;
    if (trim(line).empty()) continue;
    std::vector<std::string> f;
    std::stringstream ss(line);
    std::string field;
    while (std::getline(ss, field, ',')) f.push_back(trim(field));
    if (!line.empty() && line.back() == ',') f.push_back("");
    const std::string where = path + ":" + std::to_string(lineno) + ": ";
    if (f.size() != 4) return Error{where + "expected 4 fields, got " + std::to_string(f.size())};
    BandwidthSample s;
    if (!parseDouble(f[0], &s.time_s)) return Error{where + "time_s is not a number"};
    s.agent = f[1];
    if (!parseDouble(f[2], &s.kBps) || s.kBps < 0)
      return Error{where + "kBps must be a number >= 0"};
    if (!f[3].empty()) {
      double c = 0;
      if (!parseDouble(f[3], &c) || c < 0)
        return Error{where + "link_capacity_kBps must be empty or a number >= 0"};
      s.link_capacity_kBps = c;
    }
    out.push_back(std::move(s));
  }
  return out;
}

BandwidthSummary summarizeBandwidth(const std::vector<BandwidthSample>& samples) {
  std::map<double, double> total;  // time_s -> summed kBps
  for (const BandwidthSample& s : samples) total[s.time_s] += s.kBps;
  BandwidthSummary r;
  r.intervals = total.size();
  if (total.empty()) return r;
  double sum = 0;
  for (const auto& [t, v] : total) {
    sum += v;
    r.kBps_peak = std::max(r.kBps_peak, v);
  }
  r.kBps_mean = sum / double(total.size());
  return r;
}

}  // namespace hermes
