// Replays the bandwidth monitor against an emulated link that follows a rate
// trace, driven like an agent: every window it sends planningRate × window ×
// fill bytes (less what is still unacknowledged) in a few messages. Used by the
// estimator test and by `hermes_bench_monitor` (curve as CSV + plot).
#pragma once

#include <string>
#include <vector>

#include "hermes/agent/bandwidth_monitor.h"
#include "hermes/core/emulated_link.h"
#include "hermes/core/status.h"

namespace hermes::agent {

struct MonitorReplayParams {
  double window_s = 5.0;            ///< [s] distillation window (one budget per window)
  double fill = 0.8;                ///< budget = fill × planning rate × window
  int messages_per_window = 4;      ///< the window's bytes split into this many messages
  double min_window_bytes = 20000;  ///< [byte] sent even when the estimate is 0 (keeps probing)
  double step_s = 0.05;             ///< [s] simulation step
  std::uint64_t seed = 3;           ///< link loss draws

  Status validate() const;
};

struct MonitorCurvePoint {
  double t = 0;                ///< [s]
  double true_mbitps = 0;      ///< the trace's rate at t
  double estimate_mbitps = 0;  ///< monitor estimate at t
  bool outage = false;         ///< monitor reports an outage at t
};

/// Runs the replay until t_end (seconds); one point per step.
std::vector<MonitorCurvePoint> replayMonitor(const LinkTrace& trace,
                                             const BandwidthMonitorParams& monitor,
                                             const MonitorReplayParams& params, double t_end);

/// A rate change of the trace and how the estimate followed it.
struct MonitorStepResponse {
  double t_change = 0;        ///< [s]
  double rate_mbitps = 0;     ///< rate after the change
  double settle_s = -1;       ///< time until the estimate stays within `tolerance` (0-rate:
                              ///< until it reads 0); -1 = never within the step
  double error_after_two_windows = 0;  ///< |estimate - rate| / rate, two windows after (0-rate: estimate)
};

/// Splits the curve at the trace's rate changes and measures each response.
std::vector<MonitorStepResponse> stepResponses(const std::vector<MonitorCurvePoint>& curve,
                                               double window_s, double tolerance = 0.2);

/// time_s,true_mbitps,estimate_mbitps,outage
Status writeMonitorCurveCsv(const std::vector<MonitorCurvePoint>& curve, const std::string& path);

}  // namespace hermes::agent
