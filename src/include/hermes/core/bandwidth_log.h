// Bandwidth time series CSV (read by scripts/plot_bandwidth.py):
//   time_s,agent,kBps,link_capacity_kBps
// time_s [s] starts the sample interval; kBps [1 kB = 1000 bytes / s] is what the
// agent actually put on the link in that interval; link_capacity_kBps is the link
// rate available at time_s (shared bottleneck rate with several agents; 0 = outage;
// empty = unknown). Agent names must not contain commas or newlines.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "hermes/core/status.h"

namespace hermes {

struct BandwidthSample {
  double time_s = 0;
  std::string agent;
  double kBps = 0;
  std::optional<double> link_capacity_kBps;
};

Status writeBandwidthCsv(const std::string& path, const std::vector<BandwidthSample>& samples);
/// Errors name path, line and column.
Expected<std::vector<BandwidthSample>> readBandwidthCsv(const std::string& path);

/// Aggregate uplink rate: samples with the same time_s are summed over agents (the
/// runner writes one common, uniform sampling grid); mean and peak of that sum.
struct BandwidthSummary {
  double kBps_mean = 0;
  double kBps_peak = 0;
  size_t intervals = 0;
};
BandwidthSummary summarizeBandwidth(const std::vector<BandwidthSample>& samples);

}  // namespace hermes
