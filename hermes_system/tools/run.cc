// hermes_run: the offline runner (DESIGN §7, §8 `./hermes run`). One agent per
// --dataset; with the server (default) every agent's uplink crosses one emulated
// shared link to the edge server on a simulated clock (system::OfflineRun);
// with --no-server a single agent only tracks. Writes the results folder
// (run_results.h), evaluates against each dataset's ground truth, draws plots.
#include <chrono>
#include <atomic>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "hermes/agent/dataset_feed.h"
#include "hermes/system/offline_run.h"
#include "hermes/system/run_results.h"
#include "hermes_help/hermes_run.h"  // tools/help/hermes_run.txt

using namespace hermes;
namespace fs = std::filesystem;

namespace {

// Ctrl-C: the run stops at its next frame and writes what it has (a second one kills).
volatile std::sig_atomic_t g_interrupted = 0;
std::atomic<system::OfflineRun*> g_run{nullptr};
void onInterrupt(int) {
  g_interrupted = 1;
  if (system::OfflineRun* r = g_run.load()) r->requestStop();
  std::signal(SIGINT, SIG_DFL);
  std::signal(SIGTERM, SIG_DFL);
}

const char* const kUsage = hermes_help::kText;

int badInput(const std::string& msg) {
  std::fprintf(stderr, "hermes_run: %s\n", msg.c_str());
  return 2;
}

int failure(const std::string& msg) {
  std::fprintf(stderr, "hermes_run: %s\n", msg.c_str());
  return 1;
}

std::string folderName(const std::string& dir) {
  std::string d = dir;
  while (d.size() > 1 && d.back() == '/') d.pop_back();
  std::string name = fs::path(d).filename().string();
  if (name == "mav0") name = fs::path(d).parent_path().filename().string();
  return name.empty() || name == "." || name == ".." ? "agent" : name;
}

Status writeText(const fs::path& path, const std::string& text) {
  std::ofstream out(path);
  if (!out) return Error{"cannot write " + path.string()};
  out << text;
  out.close();
  if (!out) return Error{"error writing " + path.string()};
  return Status::Ok();
}

struct Args {
  std::vector<std::string> datasets, sets;
  std::string out, config;
  bool no_server = false, json = false, help = false, plots = true, quiet = false;
  std::string bandwidth, link_trace, scenario;
  std::string record_tracking, replay_tracking, prior_map;
  long max_frames = -1;
  std::vector<double> restart_at;
  std::vector<system::AgentReset> agent_reset;
};

/// Parses argv; returns an error message (empty: ok).
std::string parseArgs(int argc, char** argv, Args* a) {
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto value = [&](std::string* out) -> bool {
      if (i + 1 >= argc) return false;
      *out = argv[++i];
      return true;
    };
    std::string v;
    if (arg == "--help" || arg == "-h") {
      a->help = true;
    } else if (arg == "--dataset") {
      if (!value(&v)) return "--dataset needs a folder";
      a->datasets.push_back(v);
    } else if (arg == "--out") {
      if (!value(&a->out)) return "--out needs a folder";
    } else if (arg == "--config") {
      if (!value(&a->config)) return "--config needs a file";
    } else if (arg == "--set") {
      if (!value(&v)) return "--set needs key=value";
      if (v.find('=') == std::string::npos) return "--set '" + v + "' is not key=value";
      a->sets.push_back(v);
    } else if (arg == "--no-server") {
      a->no_server = true;
    } else if (arg == "--json") {
      a->json = true;
    } else if (arg == "--quiet") {
      a->quiet = true;
    } else if (arg == "--no-plots") {
      a->plots = false;
    } else if (arg == "--bandwidth") {
      if (!value(&a->bandwidth)) return "--bandwidth needs MBITPS";
      char* end = nullptr;
      const double mbit = std::strtod(a->bandwidth.c_str(), &end);
      if (end == a->bandwidth.c_str() || *end != '\0' || !(mbit > 0) || !std::isfinite(mbit))
        return "--bandwidth '" + a->bandwidth + "' is not a positive number of Mbit/s";
    } else if (arg == "--link-trace") {
      if (!value(&a->link_trace)) return "--link-trace needs a file";
    } else if (arg == "--scenario") {
      if (!value(&a->scenario)) return "--scenario needs a file";
    } else if (arg == "--server-restart-at") {
      if (!value(&v)) return "--server-restart-at needs S (simulated seconds)";
      char* end = nullptr;
      const double t = std::strtod(v.c_str(), &end);
      if (v.empty() || *end != '\0' || !(t >= 0) || !std::isfinite(t))
        return "--server-restart-at '" + v + "' is not a time >= 0 s";
      a->restart_at.push_back(t);
    } else if (arg == "--agent-reset") {
      if (!value(&v)) return "--agent-reset needs NAME@S (agent name, simulated seconds)";
      auto parsed = system::parseAgentResets(v);
      if (!parsed || parsed->size() != 1) return "--agent-reset: " + (parsed ? "'" + v + "' is not one NAME@S" : parsed.error());
      a->agent_reset.push_back(parsed->front());
    } else if (arg == "--record-tracking") {
      if (!value(&a->record_tracking)) return "--record-tracking needs a folder";
    } else if (arg == "--replay-tracking") {
      if (!value(&a->replay_tracking)) return "--replay-tracking needs a folder";
    } else if (arg == "--prior-map") {
      if (!value(&a->prior_map)) return "--prior-map needs a folder (an earlier run's OUT/map)";
    } else if (arg == "--max-frames") {
      if (!value(&v)) return "--max-frames needs N";
      char* end = nullptr;
      a->max_frames = std::strtol(v.c_str(), &end, 10);
      if (end == v.c_str() || *end != '\0' || a->max_frames <= 0)
        return "--max-frames '" + v + "' is not a positive integer";
    } else {
      return "unknown argument '" + arg + "' (see --help)";
    }
  }
  if (a->help) return "";
  if (a->datasets.empty()) return "missing --dataset DIR (see --help)";
  if (a->out.empty()) return "missing --out DIR (see --help)";
  if (int(!a->bandwidth.empty()) + int(!a->link_trace.empty()) + int(!a->scenario.empty()) > 1)
    return "--bandwidth, --link-trace and --scenario exclude each other";
  if (a->no_server && a->datasets.size() > 1)
    return "--no-server runs one agent: give one --dataset";
  if (a->no_server && (!a->bandwidth.empty() || !a->link_trace.empty() || !a->scenario.empty()))
    return "--bandwidth/--link-trace/--scenario need the server (drop --no-server)";
  if (a->no_server && !a->restart_at.empty())
    return "--server-restart-at needs the server (drop --no-server)";
  if (a->no_server && !a->agent_reset.empty())
    return "--agent-reset needs the server (drop --no-server)";
  if (a->no_server && (!a->record_tracking.empty() || !a->replay_tracking.empty()))
    return "--record-tracking / --replay-tracking need the server (drop --no-server)";
  if (a->no_server && !a->prior_map.empty()) return "--prior-map needs the server (drop --no-server)";
  return "";
}

/// Runs a python plot script from the source tree; a failure is a warning only.
void plot(const std::string& script, const std::string& args) {
  const std::string path = std::string(HERMES_SOURCE_DIR) + "/scripts/" + script;
  if (!fs::exists(path)) return;
  const std::string cmd = "/usr/bin/python3 " + path + " " + args + " >/dev/null 2>&1";
  if (std::system(cmd.c_str()) != 0)
    std::fprintf(stderr, "hermes_run: warning: plot %s failed (%s)\n", script.c_str(), cmd.c_str());
}

std::string quote(const std::string& s) { return "'" + s + "'"; }

void drawPlots(const system::OfflineRun& run, const fs::path& out) {
  const fs::path plots = out / "plots";
  std::error_code ec;
  fs::create_directories(plots, ec);
  std::string traj_args;
  for (const system::OfflineAgent& a : run.agents()) {
    const fs::path gt = out / "trajectories" / (a.name + "_gt.tum");
    const fs::path merged = out / "trajectories" / (a.name + "_merged.tum");
    if (fs::exists(gt) && fs::exists(merged))
      traj_args += " --gt " + quote(gt.string()) + " --est " + quote(merged.string()) +
                   " --name " + quote(a.name);
  }
  if (!traj_args.empty())
    plot("plot_trajectories.py", traj_args + " --align merged --metrics " +
                                     quote((out / "metrics.json").string()) + " --out " +
                                     quote((plots / "trajectories_top.png").string()));
  plot("plot_bandwidth.py", "--csv " + quote((out / "bandwidth.csv").string()) + " --out " +
                                quote((plots / "bandwidth.png").string()));
  plot("plot_ate_time.py", "--csv " + quote((out / "ate_over_time.csv").string()) + " --out " +
                               quote((plots / "ate_over_time.png").string()));
  plot("plot_pose_graph.py", "--csv " + quote((out / "pose_graph_edges.csv").string()) + " --out " +
                                 quote((plots / "pose_graph.png").string()));
}

int runNoServer(const Args& args, system::SystemParams& params, std::unique_ptr<Dataset> dataset,
                const std::string& name, const fs::path& out);

}  // namespace

int main(int argc, char** argv) {
  Args args;
  if (std::string err = parseArgs(argc, argv, &args); !err.empty()) return badInput(err);
  if (args.help) {
    std::cout << kUsage;
    return 0;
  }
  std::signal(SIGINT, onInterrupt);
  std::signal(SIGTERM, onInterrupt);
  // Paths first, so that a wrong path is reported as such.
  std::error_code ec;
  for (const std::string& d : args.datasets)
    if (!fs::is_directory(d, ec)) return badInput("dataset folder " + d + " does not exist");
  if (!args.config.empty() && !fs::is_regular_file(args.config, ec))
    return badInput("config file " + args.config + " does not exist");
  if (!args.link_trace.empty() && !fs::is_regular_file(args.link_trace, ec))
    return badInput("link trace " + args.link_trace + " does not exist");
  if (!args.scenario.empty() && !fs::is_regular_file(args.scenario, ec))
    return badInput("scenario file " + args.scenario + " does not exist");

  // Configuration: every module reads its keys, then nothing may be left over.
  std::vector<std::string> sets = args.sets;
  if (!args.bandwidth.empty()) sets.push_back("link.bandwidth_mbitps=" + args.bandwidth);
  if (!args.link_trace.empty()) sets.push_back("link.trace=" + args.link_trace);
  if (!args.scenario.empty()) sets.push_back("link.scenario=" + args.scenario);
  if (!args.record_tracking.empty()) sets.push_back("system.tracking_record_dir=" + args.record_tracking);
  if (!args.replay_tracking.empty()) sets.push_back("system.tracking_replay_dir=" + args.replay_tracking);
  if (!args.prior_map.empty()) {
    if (!fs::is_directory(args.prior_map, ec)) return badInput("prior map " + args.prior_map + " is not a folder");
    sets.push_back("server.prior_map=" + args.prior_map);
  }
  auto config = loadConfig(args.config, sets);
  if (!config.ok()) return badInput(config.error());
  auto params = system::readSystemParams(*config);
  if (!params.ok()) return badInput(params.error());
  for (double t : args.restart_at) params->clock.server_restart_at.push_back(t);
  for (const system::AgentReset& r : args.agent_reset) params->clock.agent_reset.push_back(r);

  std::vector<system::AgentSource> sources;
  std::set<std::string> names;
  for (const std::string& dir : args.datasets) {
    auto dataset = Dataset::open(dir, params->run.dataset);
    if (!dataset.ok()) return badInput("dataset " + dir + ": " + dataset.error());
    if ((*dataset)->info().frame_count == 0) return badInput("dataset " + dir + " holds no frames");
    std::string name = folderName(dir);
    for (int k = 2; names.count(name); ++k) name = folderName(dir) + "_" + std::to_string(k);
    names.insert(name);
    for (const std::string& w : (*dataset)->info().warnings)
      std::fprintf(stderr, "hermes_run: %s: warning: %s\n", name.c_str(), w.c_str());
    if (!args.quiet)
      std::fprintf(stderr, "hermes_run: %s: %s\n", name.c_str(), (*dataset)->info().summary().c_str());
    sources.push_back({name, std::move(*dataset),
                       args.max_frames > 0 ? std::size_t(args.max_frames) : std::size_t(0)});
  }

  const fs::path out(args.out);
  fs::create_directories(out / "trajectories", ec);
  if (ec || !fs::is_directory(out, ec)) return badInput("cannot create output folder " + out.string());
  if (!params->clock.server_restart_at.empty() && !params->server.checkpoint.enabled())
    params->server.checkpoint.dir = (out / "server_checkpoint").string();
  if (Status s = writeText(out / "config_used.yaml", params->yaml()); !s) return failure(s.error());
  for (const system::AgentSource& s : sources)
    if (!s.dataset->info().groundtruth.empty())
      if (Status st = writeTumTrajectory((out / "trajectories" / (s.name + "_gt.tum")).string(),
                                         s.dataset->info().groundtruth);
          !st)
        return failure(st.error());

  if (args.no_server)
    return runNoServer(args, *params, std::move(sources.front().dataset), sources.front().name, out);

  auto run = system::OfflineRun::create(*params, std::move(sources), (out / "spool").string(),
                                        HERMES_SOURCE_DIR);
  if (!run.ok()) return badInput(run.error());
  g_run.store(run->get());
  if (g_interrupted) (*run)->requestStop();
  std::vector<server::LoopAttempt> attempts;
  (*run)->onServerCreated([&attempts](server::Server& srv) {
    srv.mapManager().setAttemptHook([&attempts](const server::LoopAttempt& a) { attempts.push_back(a); });
  });
  using Clock = std::chrono::steady_clock;
  const auto t_start = Clock::now();
  auto wall = [&] { return std::chrono::duration<double>(Clock::now() - t_start).count(); };
  double last_report = -10;
  Status s = (*run)->run([&](const system::ProgressInfo& p) {
    if (args.quiet || wall() - last_report < 2.0) return;
    last_report = wall();
    std::fprintf(stderr,
                 "hermes_run: sim %6.1f/%.1f s%s  frames %zu/%zu  submaps merged %d  agents "
                 "merged %d  wall %.0f s\n",
                 p.sim_time, p.sim_end, p.draining ? " (delivering backlog)" : "", p.frames_done,
                 p.frames_total, p.merged_submaps, p.agents_merged, wall());
  });
  g_run.store(nullptr);
  if (!s) {  // what was merged until the error is still written, marked incomplete
    if ((*run)->hasServer()) {
      system::RunResults partial = system::evaluateRun(**run);
      partial.metrics.incomplete = true;
      partial.metrics.stopped_because = s.error();
      if (Status w = system::writeRunResults(**run, partial, out.string()); w.ok() &&
          system::saveMapToResume((*run)->server(), (out / "map").string()))
        std::fprintf(stderr, "hermes_run: the results so far are in %s (marked incomplete)\n",
                     out.string().c_str());
    }
    return failure(s.error());
  }
  const double wall_s = wall();
  const system::RunResults results = system::evaluateRun(**run);
  if (Status w = system::writeRunResults(**run, results, out.string()); !w) return failure(w.error());
  if (Status w = system::saveMapToResume((*run)->server(), (out / "map").string()); !w)
    return failure(w.error());
  if (Status w = system::writeLoopAttempts(**run, attempts, (out / "loop_attempts.csv").string()); !w)
    return failure(w.error());
  if (args.plots) drawPlots(**run, out);
  if (args.json) {
    std::cout << system::resultsJson(results).dump(2) << "\n";
  } else {
    std::printf("%s", system::formatReport(**run, results).c_str());
    std::printf("simulated %.1f s in %.1f s wall; results in %s%s\n", (*run)->simTime(), wall_s,
                out.string().c_str(), (*run)->stoppedEarly() ? " (incomplete: interrupted)" : "");
  }
  return (*run)->stoppedEarly() ? 130 : 0;
}

namespace {

int runNoServer(const Args& args, system::SystemParams& params, std::unique_ptr<Dataset> dataset,
                const std::string& name, const fs::path& out) {
  const DatasetInfo& info = dataset->info();
  // A relative spool folder lives under the output folder (unused without uplink).
  if (fs::path(params.run.agent.uplink.buffer.dir).is_relative())
    params.run.agent.uplink.buffer.dir = (out / params.run.agent.uplink.buffer.dir).string();
  agent::AgentCamera camera{info.K, info.baseline, info.T_B_C};
  auto pipeline = agent::AgentPipeline::create(params.offlineAgent(), name, camera);
  if (!pipeline.ok()) return badInput(pipeline.error());
  std::size_t n = info.frame_count;
  if (args.max_frames > 0 && std::size_t(args.max_frames) < n) n = std::size_t(args.max_frames);
  TimingStats io_timings;
  using Clock = std::chrono::steady_clock;
  const auto t_start = Clock::now();
  auto seconds = [&] { return std::chrono::duration<double>(Clock::now() - t_start).count(); };
  double last_report = 0;
  FrameSkips skips;
  std::string stopped;  // why the run ended before its last frame; empty: it did not
  for (std::size_t i = 0; i < n; ++i) {
    if (g_interrupted) {
      stopped = "interrupted at frame " + std::to_string(i);
      break;
    }
    const auto t0 = Clock::now();
    auto frame = loadCameraFrame(*dataset, i);
    io_timings.add("load", std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
    if (!frame.ok()) {  // costs this frame, not the run
      if (skips.add(frame.error()))
        std::fprintf(stderr, "hermes_run: warning: frame %zu skipped (%s); further frames of this "
                     "cause are counted\n", i, frame.error().c_str());
      continue;
    }
    auto result = (*pipeline)->feed(*frame);
    if (!result.ok()) {
      stopped = "frame " + std::to_string(i) + ": " + result.error();
      break;
    }
    const double now = seconds();
    if (!args.quiet && (now - last_report >= 2.0 || i + 1 == n)) {
      last_report = now;
      std::fprintf(stderr, "hermes_run: %s frame %zu/%zu  %.1f fps  state %s  lost %.1f %%\n",
                   name.c_str(), i + 1, n, double(i + 1) / std::max(now, 1e-9),
                   toString(result->status), 100.0 * (*pipeline)->lostRate());
    }
  }
  const double wall_s = seconds();
  const agent::AgentPipeline& agent = **pipeline;
  if (Status s = writeTumTrajectory((out / "trajectories" / (name + "_raw.tum")).string(),
                                    agent.trajectory());
      !s)
    return failure(s.error());

  RunMetrics metrics;
  metrics.per_agent.push_back(agent.metrics());
  metrics.per_agent.back().submaps_applied = 0;
  metrics.per_agent.back().frames_skipped = skips.total();
  metrics.per_agent.back().frames_skipped_causes = skips.byCause();
  if (!stopped.empty()) {
    metrics.incomplete = true;
    metrics.stopped_because = stopped;
  }
  metrics.bytes_total = agent.bytesSent();
  TimingStats timings = agent.timings();
  timings.merge(io_timings);
  metrics.timings_ms = timings.summary();
  std::string ate_text = "no ground truth";
  if (!info.groundtruth.empty()) {
    if (agent.trajectory().empty()) {
      ate_text = "no tracked pose to evaluate";
    } else {
      auto ev = eval::evaluateAgents({{name, info.groundtruth, agent.trajectory()}},
                                     params.run.eval);
      if (ev.ok()) {
        fillAccuracy(*ev, params.run.eval, &metrics);
        metrics.per_agent.back().raw_ate_rmse_m = metrics.per_agent.back().ate_rmse_m;
        char buf[160];
        std::snprintf(buf, sizeof buf, "ATE %.4f m (%s, %zu poses matched)",
                      ev->agents.front().ate.trans_m.rmse, toString(params.run.eval.align),
                      ev->agents.front().assoc.matched());
        ate_text = buf;
      } else {
        ate_text = "evaluation failed: " + ev.error();
        std::fprintf(stderr, "hermes_run: warning: %s\n", ate_text.c_str());
      }
    }
  }
  if (Status s = writeMetricsJson((out / "metrics.json").string(), metrics); !s)
    return failure(s.error());
  if (args.json) {
    std::cout << metricsToJsonString(metrics) << "\n";
  } else {
    std::printf("%s: %zu frames in %.1f s (%.1f fps), lost %.2f %%, %lld keyframes, %lld "
                "landmarks, %s\n",
                name.c_str(), n, wall_s, double(n) / std::max(wall_s, 1e-9),
                100.0 * agent.lostRate(), static_cast<long long>(agent.tracker().keyframes().size()),
                static_cast<long long>(agent.tracker().landmarks().size()), ate_text.c_str());
    for (const auto& [stage, t] : metrics.timings_ms)
      std::printf("  %-12s median %7.2f ms  p95 %7.2f ms  (%lld)\n", stage.c_str(), t.median,
                  t.p95, static_cast<long long>(t.count));
    if (skips.total() > 0) std::printf("  %s\n", skips.summary().c_str());
    std::printf("results in %s%s\n", out.string().c_str(), stopped.empty() ? "" : " (incomplete)");
  }
  if (!stopped.empty()) return g_interrupted ? 130 : failure(stopped);
  return 0;
}

}  // namespace
