// A sample of values as the benchmarks print it: {median, p95, max, mean, n}
// with nearest-rank quantiles (the value at rank round(q * (n - 1)) of the sorted
// sample); an empty sample gives null.
#pragma once

#include <vector>

#include <nlohmann/json_fwd.hpp>

namespace hermes {

nlohmann::json distributionJson(std::vector<double> values);

}  // namespace hermes
