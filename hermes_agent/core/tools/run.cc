// hermes_run: the offline runner (DESIGN §7, §8 `./hermes run`). For now one
// agent without server (--no-server): opens the dataset, feeds every frame to
// the AgentPipeline, writes OUT/config_used.yaml, OUT/<agent>_raw.txt (TUM, body
// poses) and OUT/metrics.json, evaluates against the dataset's ground truth.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "hermes/agent/agent_pipeline.h"
#include "hermes/agent/run_config.h"
#include "hermes/core/dataset.h"
#include "hermes/core/evaluation.h"
#include "hermes/core/metrics.h"

using namespace hermes;
namespace fs = std::filesystem;

namespace {

const char* kUsage =
    "usage: hermes_run --dataset DIR [--dataset DIR2 ...] --out DIR [--config FILE]\n"
    "                  [--set key=value ...] [--no-server]\n"
    "                  [--bandwidth MBITPS | --link-trace FILE] [--max-frames N] [--json]\n"
    "Runs one agent per dataset (EuRoC ASL stereo or TUM RGB-D layout) and writes\n"
    "  OUT/config_used.yaml   every parameter actually used\n"
    "  OUT/<agent>_raw.txt    the agent's body trajectory (TUM format, odometry frame)\n"
    "  OUT/metrics.json       DESIGN §7 metrics (ATE when the dataset has ground truth)\n"
    "<agent> is the dataset folder's name. --config: YAML (default: built-in defaults,\n"
    "see config/hermes.yaml); --set overrides one key (unknown keys are an error).\n"
    "--max-frames: stop after N frames. --json: print metrics.json to stdout instead of\n"
    "the summary. Implemented so far: --no-server with one --dataset (multi-agent and\n"
    "server runs, --bandwidth and --link-trace exit 2).\n"
    "Exit: 0 ok, 1 failure while running, 2 bad input or not implemented.\n";

int badInput(const std::string& msg) {
  std::fprintf(stderr, "hermes_run: %s\n", msg.c_str());
  return 2;
}

int failure(const std::string& msg) {
  std::fprintf(stderr, "hermes_run: %s\n", msg.c_str());
  return 1;
}

std::string agentName(const std::string& dir) {
  std::string d = dir;
  while (d.size() > 1 && d.back() == '/') d.pop_back();
  std::string name = fs::path(d).filename().string();
  return name.empty() || name == "." || name == ".." ? "agent0" : name;
}

Expected<CameraFrame> loadFrame(const Dataset& dataset, std::size_t i) {
  CameraFrame frame;
  if (dataset.info().kind == DatasetKind::kEuroc) {
    auto f = dataset.loadStereo(i);
    if (!f.ok()) return Error{f.error()};
    frame.stamp = f->t;
    frame.left = f->left;
    frame.right = f->right;
  } else {
    auto f = dataset.loadRgbd(i);
    if (!f.ok()) return Error{f.error()};
    frame.stamp = f->t;
    frame.left = f->gray;
    frame.depth = f->depth_m;
  }
  return frame;
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
  bool no_server = false, json = false, help = false;
  std::string bandwidth, link_trace;
  long max_frames = -1;
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
    } else if (arg == "--bandwidth") {
      if (!value(&a->bandwidth)) return "--bandwidth needs MBITPS";
      char* end = nullptr;
      const double mbit = std::strtod(a->bandwidth.c_str(), &end);
      if (end == a->bandwidth.c_str() || *end != '\0' || !(mbit > 0) || !std::isfinite(mbit))
        return "--bandwidth '" + a->bandwidth + "' is not a positive number of Mbit/s";
    } else if (arg == "--link-trace") {
      if (!value(&a->link_trace)) return "--link-trace needs a file";
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
  if (!a->bandwidth.empty() && !a->link_trace.empty())
    return "--bandwidth and --link-trace exclude each other";
  return "";
}

}  // namespace

int main(int argc, char** argv) {
  Args args;
  if (std::string err = parseArgs(argc, argv, &args); !err.empty()) return badInput(err);
  if (args.help) {
    std::cout << kUsage;
    return 0;
  }
  // Paths first, so that a wrong path is reported as such.
  for (const std::string& d : args.datasets) {
    std::error_code ec;
    if (!fs::is_directory(d, ec)) return badInput("dataset folder " + d + " does not exist");
  }
  if (!args.config.empty()) {
    std::error_code ec;
    if (!fs::is_regular_file(args.config, ec))
      return badInput("config file " + args.config + " does not exist");
  }
  if (!args.link_trace.empty()) {
    std::error_code ec;
    if (!fs::is_regular_file(args.link_trace, ec))
      return badInput("link trace " + args.link_trace + " does not exist");
  }
  if (args.datasets.size() > 1 || !args.no_server || !args.bandwidth.empty() ||
      !args.link_trace.empty())
    return badInput(
        "not implemented yet: multi-agent/server runs (--bandwidth, --link-trace, several "
        "--dataset, or no --no-server); use --no-server with one --dataset");

  // Configuration: every module reads its keys, then nothing may be left over.
  auto config = agent::loadRunConfig(args.config, args.sets);
  if (!config.ok()) return badInput(config.error());
  auto params = agent::readRunParams(*config);
  if (!params.ok()) return badInput(params.error());

  const std::string& dir = args.datasets.front();
  auto dataset = Dataset::open(dir, params->dataset);
  if (!dataset.ok()) return badInput("dataset " + dir + ": " + dataset.error());
  const DatasetInfo& info = (*dataset)->info();
  if (info.frame_count == 0) return badInput("dataset " + dir + " holds no frames");

  const fs::path out(args.out);
  {
    std::error_code ec;
    fs::create_directories(out, ec);
    if (ec || !fs::is_directory(out, ec))
      return badInput("cannot create output folder " + out.string());
  }
  // A relative spool folder lives under the output folder.
  if (fs::path(params->agent.uplink.buffer.dir).is_relative())
    params->agent.uplink.buffer.dir = (out / params->agent.uplink.buffer.dir).string();
  if (Status s = writeText(out / "config_used.yaml", agent::configUsedYaml(*params)); !s)
    return failure(s.error());

  const std::string name = agentName(dir);
  agent::AgentCamera camera{info.K, info.baseline, info.T_B_C};
  auto pipeline = agent::AgentPipeline::create(params->agent, name, camera);
  if (!pipeline.ok()) return badInput(pipeline.error());
  for (const std::string& w : info.warnings) std::fprintf(stderr, "hermes_run: warning: %s\n", w.c_str());
  std::fprintf(stderr, "hermes_run: %s: %s\n", name.c_str(), info.summary().c_str());

  std::size_t n = info.frame_count;
  if (args.max_frames > 0 && std::size_t(args.max_frames) < n) n = std::size_t(args.max_frames);
  TimingStats io_timings;
  using Clock = std::chrono::steady_clock;
  const auto t_start = Clock::now();
  auto seconds = [&] { return std::chrono::duration<double>(Clock::now() - t_start).count(); };
  double last_report = 0;
  std::string state = "-";
  for (std::size_t i = 0; i < n; ++i) {
    const auto t0 = Clock::now();
    auto frame = loadFrame(**dataset, i);
    io_timings.add("load", std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
    if (!frame.ok()) return failure("frame " + std::to_string(i) + ": " + frame.error());
    auto result = (*pipeline)->feed(*frame);
    if (!result.ok()) return failure("frame " + std::to_string(i) + ": " + result.error());
    state = toString(result->status);
    const double now = seconds();
    if (now - last_report >= 2.0 || i + 1 == n) {
      last_report = now;
      std::fprintf(stderr, "hermes_run: %s frame %zu/%zu  %.1f fps  state %s  lost %.1f %%\n",
                   name.c_str(), i + 1, n, double(i + 1) / std::max(now, 1e-9), state.c_str(),
                   100.0 * (*pipeline)->lostRate());
    }
  }
  const double wall_s = seconds();
  const agent::AgentPipeline& agent = **pipeline;

  const fs::path traj_path = out / (name + "_raw.txt");
  if (Status s = writeTumTrajectory(traj_path.string(), agent.trajectory()); !s)
    return failure(s.error());

  RunMetrics metrics;
  metrics.per_agent.push_back(agent.metrics());
  metrics.per_agent.back().submaps_applied = 0;
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
                                     params->eval);
      if (ev.ok()) {
        fillAccuracy(*ev, params->eval, &metrics);
        char buf[160];
        std::snprintf(buf, sizeof buf, "ATE %.4f m (%s, %zu poses matched)",
                      ev->agents.front().ate.trans_m.rmse, toString(params->eval.align),
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
    std::printf("results in %s\n", out.string().c_str());
  }
  return 0;
}
