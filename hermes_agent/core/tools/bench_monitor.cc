// hermes_bench_monitor: the bandwidth monitor against an emulated link following
// a rate trace (default: the issue's 30 -> 10 -> 2 -> 0 (30 s outage) -> 20 Mbit/s),
// driven like an agent (one budget per 5-s window). Writes the curve as CSV and a
// plot, prints JSON with the response to every rate change and the outage delay.
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>

#include <nlohmann/json.hpp>

#include "hermes/agent/monitor_replay.h"
#include "hermes_help/hermes_bench_monitor.h"  // tools/help/hermes_bench_monitor.txt

namespace fs = std::filesystem;
using namespace hermes;
using namespace hermes::agent;

namespace {

const char* const kUsage = hermes_help::kText;

const char* kIssueTrace =
    "time_s,rate_mbitps,latency_ms,loss\n0,30,5,0\n60,10,5,0\n120,2,5,0\n180,0,5,0\n210,20,5,0\n";

}  // namespace

int main(int argc, char** argv) {
  std::string trace_path, json_out, out_dir = "results/bench_monitor";
  double duration = 270;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "hermes_bench_monitor: %s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--help" || a == "-h") {
      std::cout << kUsage;
      return 0;
    } else if (a == "--trace") {
      trace_path = next();
    } else if (a == "--duration") {
      duration = std::atof(next().c_str());
    } else if (a == "--out") {
      out_dir = next();
    } else if (a == "--json") {
      json_out = next();
    } else {
      std::fprintf(stderr, "hermes_bench_monitor: unknown argument '%s' (see --help)\n", a.c_str());
      return 2;
    }
  }
  if (!(duration > 0)) {
    std::fprintf(stderr, "hermes_bench_monitor: --duration must be > 0\n");
    return 2;
  }
  auto trace = trace_path.empty() ? LinkTrace::fromString(kIssueTrace, "issue trace")
                                  : LinkTrace::fromCsv(trace_path);
  if (!trace) {
    std::fprintf(stderr, "hermes_bench_monitor: %s\n", trace.error().c_str());
    return 2;
  }
  const BandwidthMonitorParams mp;
  const MonitorReplayParams rp;
  const auto curve = replayMonitor(*trace, mp, rp, duration);

  std::error_code ec;
  fs::create_directories(out_dir, ec);
  const fs::path csv = fs::path(out_dir) / "monitor_curve.csv";
  const fs::path png = fs::path(out_dir) / "monitor_curve.png";
  if (Status s = writeMonitorCurveCsv(curve, csv.string()); !s) {
    std::fprintf(stderr, "hermes_bench_monitor: %s\n", s.error().c_str());
    return 1;
  }
  const fs::path script = fs::path(HERMES_SOURCE_DIR) / "scripts" / "plot_monitor.py";
  const std::string cmd = "/usr/bin/python3 '" + script.string() + "' --csv '" + csv.string() +
                          "' --out '" + png.string() + "' >/dev/null 2>&1";
  const bool plotted = fs::exists(script) && std::system(cmd.c_str()) == 0;
  if (!plotted) std::fprintf(stderr, "hermes_bench_monitor: warning: plot failed (%s)\n", cmd.c_str());

  nlohmann::json steps = nlohmann::json::array();
  bool pass = true;
  for (const MonitorStepResponse& r : stepResponses(curve, rp.window_s)) {
    steps.push_back({{"t_change_s", r.t_change},
                     {"rate_mbitps", r.rate_mbitps},
                     {"settle_s", r.settle_s},
                     {"error_after_two_windows", r.error_after_two_windows}});
    if (r.rate_mbitps > 0)
      pass = pass && r.settle_s >= 0 && r.settle_s <= 2 * rp.window_s && r.error_after_two_windows <= 0.2;
  }
  nlohmann::json outages = nlohmann::json::array();
  for (std::size_t i = 1; i < curve.size(); ++i) {
    if (curve[i].true_mbitps == 0 && curve[i - 1].true_mbitps > 0) {
      double detected = -1;
      for (std::size_t k = i; k < curve.size() && curve[k].true_mbitps == 0; ++k)
        if (curve[k].outage) { detected = curve[k].t - curve[i].t; break; }
      outages.push_back({{"t_start_s", curve[i].t}, {"detected_after_s", detected}});
      pass = pass && detected >= 0 && detected <= mp.outage_timeout_s + rp.window_s;
    }
  }
  const nlohmann::json j = {{"benchmark", "monitor"},
                            {"trace", trace_path.empty() ? "issue 30-10-2-0-20" : trace_path},
                            {"monitor_window_s", mp.window_s},
                            {"outage_timeout_s", mp.outage_timeout_s},
                            {"submap_window_s", rp.window_s},
                            {"steps", steps},
                            {"outages", outages},
                            {"pass", pass},
                            {"csv", csv.string()},
                            {"plot", plotted ? png.string() : ""}};
  std::cout << j.dump(2) << "\n";
  if (!json_out.empty()) std::ofstream(json_out) << j.dump(2) << "\n";
  return 0;
}
