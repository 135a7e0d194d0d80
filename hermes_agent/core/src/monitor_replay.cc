#include "hermes/agent/monitor_replay.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>

namespace hermes::agent {

Status MonitorReplayParams::validate() const {
  if (!(window_s > 0)) return Error{"monitor replay: window_s must be > 0"};
  if (!(fill > 0 && fill <= 1)) return Error{"monitor replay: fill must be in (0, 1]"};
  if (messages_per_window < 1) return Error{"monitor replay: messages_per_window must be >= 1"};
  if (!(min_window_bytes > 0)) return Error{"monitor replay: min_window_bytes must be > 0"};
  if (!(step_s > 0 && step_s < window_s)) return Error{"monitor replay: step_s must be in (0, window_s)"};
  return Status::Ok();
}

std::vector<MonitorCurvePoint> replayMonitor(const LinkTrace& trace,
                                             const BandwidthMonitorParams& monitor_params,
                                             const MonitorReplayParams& p, double t_end) {
  HERMES_CHECK(p.validate().ok(), p.validate().error());
  SharedLink link(trace, 1, p.seed);
  BandwidthMonitor monitor(monitor_params);
  std::vector<MonitorCurvePoint> curve;
  std::uint64_t next_id = 0;
  double next_window = 0;
  const int steps = static_cast<int>(std::ceil(t_end / p.step_s));
  for (int i = 0; i <= steps; ++i) {
    const double t = i * p.step_s;
    if (t >= next_window) {
      const double backlog = static_cast<double>(monitor.outstandingBytes());
      monitor.onWindowDelivered(backlog < 1.0);
      const double budget = p.fill * monitor.planningRate(t) * p.window_s;
      const double bytes = std::max(p.min_window_bytes, budget - backlog);
      for (int k = 0; k < p.messages_per_window; ++k) {
        LinkMessage m;
        m.id = next_id++;
        m.bytes = static_cast<std::size_t>(bytes / p.messages_per_window);
        monitor.onSend(m.id, m.bytes, t);
        link.send(m, t);
      }
      next_window += p.window_s;
    }
    for (const LinkDelivery& d : link.advanceTo(t)) {
      if (d.lost) continue;
      const double ack = link.ackArrival(d.arrival_time);
      if (ack >= 0) monitor.onAck(d.message.id, ack);
    }
    curve.push_back({t, trace.at(t).rate_mbitps, monitor.estimate(t) * 8e-6, monitor.outage(t)});
  }
  return curve;
}

std::vector<MonitorStepResponse> stepResponses(const std::vector<MonitorCurvePoint>& curve,
                                               double window_s, double tolerance) {
  std::vector<MonitorStepResponse> out;
  std::size_t begin = 0;
  while (begin < curve.size()) {
    std::size_t end = begin;
    while (end < curve.size() && curve[end].true_mbitps == curve[begin].true_mbitps) ++end;
    MonitorStepResponse r;
    r.t_change = curve[begin].t;
    r.rate_mbitps = curve[begin].true_mbitps;
    auto within = [&](const MonitorCurvePoint& c) {
      return r.rate_mbitps > 0 ? std::abs(c.estimate_mbitps - r.rate_mbitps) <= tolerance * r.rate_mbitps
                               : c.estimate_mbitps == 0.0;
    };
    // Settled: within from this point to the end of the step.
    for (std::size_t i = end; i-- > begin;) {
      if (!within(curve[i])) break;
      r.settle_s = curve[i].t - r.t_change;
    }
    const double t2 = r.t_change + 2 * window_s;
    std::size_t k = begin;
    while (k + 1 < end && curve[k].t < t2) ++k;
    r.error_after_two_windows =
        r.rate_mbitps > 0 ? std::abs(curve[k].estimate_mbitps - r.rate_mbitps) / r.rate_mbitps
                          : curve[k].estimate_mbitps;
    out.push_back(r);
    begin = end;
  }
  return out;
}

Status writeMonitorCurveCsv(const std::vector<MonitorCurvePoint>& curve, const std::string& path) {
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> f(std::fopen(path.c_str(), "w"), &std::fclose);
  if (!f) return Error{"cannot write " + path};
  std::fprintf(f.get(), "time_s,true_mbitps,estimate_mbitps,outage\n");
  for (const MonitorCurvePoint& c : curve)
    std::fprintf(f.get(), "%.2f,%.3f,%.3f,%d\n", c.t, c.true_mbitps, c.estimate_mbitps, c.outage ? 1 : 0);
  if (std::ferror(f.get())) return Error{"write error on " + path};
  return Status::Ok();
}

}  // namespace hermes::agent
