#include "hermes/core/value_stats.h"

#include <algorithm>
#include <cstddef>

#include <nlohmann/json.hpp>

namespace hermes {

nlohmann::json distributionJson(std::vector<double> v) {
  nlohmann::json j;
  if (v.empty()) return j;
  std::sort(v.begin(), v.end());
  auto q = [&](double f) { return v[std::min(v.size() - 1, static_cast<std::size_t>(f * (v.size() - 1) + 0.5))]; };
  double sum = 0;
  for (double x : v) sum += x;
  j["median"] = q(0.5);
  j["p95"] = q(0.95);
  j["max"] = v.back();
  j["mean"] = sum / static_cast<double>(v.size());
  j["n"] = v.size();
  return j;
}

}  // namespace hermes
