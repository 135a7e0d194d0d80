// hermes_bench_server: processing time of the server pipeline per submap
// (median / p95) and per stage, for 3 and 10 simulated agents on EuRoC
// ground-truth trajectories sharing one hall. Prints JSON (also to --json FILE).
// With --acks MS: the acknowledgement latency instead (frame due -> verdict
// back, median / p95 / max [ms]) when the frames arrive every MS milliseconds
// in real time, for one thread that receives and merges (a ROS node with one
// spinner, as before issue 17) and for ServerWorker (merging on its thread).
//
// Usage: tools/help/hermes_bench_server.txt (`hermes_bench_server --help`).
#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "hermes/core/evaluation.h"
#include "hermes/server/server.h"
#include "hermes/server/server_outputs.h"
#include "hermes/server/server_worker.h"
#include "hermes_help/hermes_bench_server.h"  // tools/help/hermes_bench_server.txt
// The multi-agent fixture lives with the tests (tools cannot link the test
// support library without a CMake change); compile it into this tool.
#include "../test/support/multi_agent_fixture.cc"

namespace {

using namespace hermes;
using namespace hermes::server;

std::string g_source_dir, g_data_dir;
ServerParams g_params;

/// --source / --data, else the environment, else relative to this executable
/// (<repo>/<build>/bin/hermes_bench_server); trajectories from <source>/config/trajectories.
void locateDirs(const char* argv0) {
  std::error_code ec;
  const auto exe = std::filesystem::canonical(std::filesystem::path(argv0), ec);
  const auto repo = ec ? std::filesystem::path(".") : exe.parent_path().parent_path().parent_path();
  if (g_source_dir.empty()) {
    if (const char* env = std::getenv("HERMES_SOURCE_DIR")) g_source_dir = env;
    else g_source_dir = repo.string();
  }
  if (g_data_dir.empty()) {
    g_data_dir = (std::filesystem::path(g_source_dir) / "config" / "trajectories").string();
  }
}

std::vector<fixture::AgentSpec> specsFor(int n) {
  const std::string gt = g_data_dir + "/";
  const char* files[3] = {"MH_01_easy.txt", "MH_02_easy.txt", "MH_03_medium.txt"};
  const double ends[3] = {20.0, 21.0, 17.0};
  std::vector<fixture::AgentSpec> specs;
  for (int i = 0; i < n; ++i) {
    const int f = i % 3;
    const double shift = 1.0 * (i / 3);  // later agents start a little later
    specs.push_back({gt + files[f], shift, ends[f] + shift * 0.2, -1});
  }
  return specs;
}

Expected<nlohmann::json> run(int n, int keypoints) {
  fixture::Options options;
  options.keypoints = keypoints;
  options.landmarks_per_keyframe = n > 3 ? 15 : 40;
  auto fx = fixture::makeFixture(specsFor(n), options);
  if (!fx) return Error{fx.error()};
  auto server = Server::create(g_params, g_source_dir);
  if (!server) return Error{server.error()};
  Server& s = **server;
  std::size_t rounds = 0, submaps = 0, keyframes = 0;
  for (const auto& a : fx->agents) {
    rounds = std::max(rounds, a.frames.size());
    submaps += a.frames.size();
    keyframes += a.keyframes;
  }
  const auto t0 = std::chrono::steady_clock::now();
  double now = 0;
  for (std::size_t r = 0; r < rounds; ++r) {
    for (const auto& a : fx->agents) {
      if (r >= a.frames.size()) continue;
      now += 1.0;
      s.onFrame(a.frames[r].data(), a.frames[r].size(), nullptr, now);
    }
    s.process(now, -1);
  }
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  nlohmann::json j;
  j["agents"] = n;
  j["submaps"] = submaps;
  j["keyframes"] = keyframes;
  j["keypoints_per_keyframe"] = keypoints;
  j["wall_s"] = wall;
  j["merge_errors"] = s.counters().merge_errors;
  j["loops_accepted"] = s.mapManager().loopsAccepted();
  j["loops_rejected"] = s.mapManager().loopsRejected();
  j["agents_merged"] = s.mapManager().agentsMerged();
  nlohmann::json stages = nlohmann::json::object();
  for (const auto& [name, st] : s.timings().summary()) {
    stages[name] = {{"median_ms", st.median}, {"p95_ms", st.p95}, {"count", st.count}};
    if (name == "submap") j["per_submap_ms"] = {{"median", st.median}, {"p95", st.p95}};
  }
  j["stages"] = stages;
  std::vector<eval::AgentTrajectories> agents;
  for (std::size_t i = 0; i < fx->agents.size(); ++i) {
    const auto robot = s.bookkeeper().robotOf(fx->agents[i].uuid);
    if (!robot) continue;
    agents.push_back({"agent" + std::to_string(i), fx->agents[i].gt_body,
                      agentTrajectory(s.map(), *robot, fx->T_B_C)});
  }
  eval::EvalParams ep;
  ep.max_dt = 0.01;
  auto ev = eval::evaluateAgents(agents, ep, /*allow_partial=*/true);
  if (ev) {
    j["merged_ate_rmse_m"] = ev->merged_ate.trans_m.rmse;
    j["agents_evaluated"] = ev->agents.size();
  }
  return j;
}

using SteadyClock = std::chrono::steady_clock;

double msBetween(SteadyClock::time_point a, SteadyClock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

nlohmann::json latencySummary(std::vector<double> ms, double wall_s) {
  const double max = ms.empty() ? 0 : *std::max_element(ms.begin(), ms.end());
  return {{"median_ms", timing::percentile(ms, 50)}, {"p95_ms", timing::percentile(ms, 95)},
          {"max_ms", max}, {"frames", ms.size()}, {"wall_s", wall_s}};
}

/// One thread receives and merges: a frame that falls due during a merge waits for it.
Expected<nlohmann::json> acksSerial(const std::vector<const std::vector<std::uint8_t>*>& frames,
                                    double interval_ms) {
  auto server = Server::create(g_params, g_source_dir);
  if (!server) return Error{server.error()};
  Server& s = **server;
  const auto start = SteadyClock::now();
  const auto due = [&](std::size_t i) {
    return start + std::chrono::microseconds(static_cast<std::int64_t>(i * interval_ms * 1e3));
  };
  std::vector<double> latency;
  std::size_t next = 0;
  while (next < frames.size() || s.pending() > 0) {
    const auto now = SteadyClock::now();
    if (next < frames.size() && now >= due(next)) {
      s.onFrame(frames[next]->data(), frames[next]->size(), nullptr, msBetween(start, now) / 1e3);
      latency.push_back(msBetween(due(next), SteadyClock::now()));
      ++next;
    } else if (s.pending() > 0) {
      s.process(msBetween(start, now) / 1e3, 1);
    } else {
      std::this_thread::sleep_until(due(next));  // idle until the next frame is due
    }
  }
  return latencySummary(latency, msBetween(start, SteadyClock::now()) / 1e3);
}

/// ServerWorker: frames received on this thread, merged on the worker's.
Expected<nlohmann::json> acksThreaded(const std::vector<const std::vector<std::uint8_t>*>& frames,
                                      double interval_ms) {
  auto server = Server::create(g_params, g_source_dir);
  if (!server) return Error{server.error()};
  const auto start = SteadyClock::now();
  ServerWorker worker(std::move(*server), ServerWorkerParams{},
                      [start] { return msBetween(start, SteadyClock::now()) / 1e3; });
  std::vector<double> latency;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const auto due = start + std::chrono::microseconds(static_cast<std::int64_t>(i * interval_ms * 1e3));
    std::this_thread::sleep_until(due);
    worker.onFrame(frames[i]->data(), frames[i]->size(), nullptr, msBetween(start, SteadyClock::now()) / 1e3);
    latency.push_back(msBetween(due, SteadyClock::now()));
  }
  worker.waitIdle();
  return latencySummary(latency, msBetween(start, SteadyClock::now()) / 1e3);
}

Expected<nlohmann::json> runAcks(int n, int keypoints, double interval_ms) {
  fixture::Options options;
  options.keypoints = keypoints;
  options.landmarks_per_keyframe = n > 3 ? 15 : 40;
  auto fx = fixture::makeFixture(specsFor(n), options);
  if (!fx) return Error{fx.error()};
  const auto frames = fixture::roundRobin(*fx);
  auto serial = acksSerial(frames, interval_ms);
  if (!serial) return serial;
  auto threaded = acksThreaded(frames, interval_ms);
  if (!threaded) return threaded;
  return nlohmann::json{{"agents", n},
                        {"submaps", frames.size()},
                        {"interval_ms", interval_ms},
                        {"one_thread", *serial},
                        {"server_worker", *threaded}};
}

}  // namespace

int main(int argc, char** argv) {
  std::string json_path;
  std::vector<int> counts = {3, 10};
  int keypoints = 200;
  double acks_interval_ms = 0;  // > 0: the acknowledgement latency bench
  Config config;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--help" || a == "-h") {
      std::cout << hermes_help::kText;
      return 0;
    } else if (a == "--json" && i + 1 < argc) {
      json_path = argv[++i];
    } else if (a == "--agents" && i + 1 < argc) {
      counts.clear();
      std::stringstream ss(argv[++i]);
      std::string item;
      while (std::getline(ss, item, ',')) counts.push_back(std::atoi(item.c_str()));
    } else if (a == "--set" && i + 1 < argc) {
      if (Status st = config.applyOverride(argv[++i]); !st) {
        std::cerr << "hermes_bench_server: " << st.error() << "\n";
        return 2;
      }
    } else if (a == "--source" && i + 1 < argc) {
      g_source_dir = argv[++i];
    } else if (a == "--data" && i + 1 < argc) {
      g_data_dir = argv[++i];
    } else if (a == "--keypoints" && i + 1 < argc) {
      keypoints = std::atoi(argv[++i]);
    } else if (a == "--acks" && i + 1 < argc) {
      acks_interval_ms = std::atof(argv[++i]);
    } else {
      std::cerr << hermes_help::kText;
      return 2;
    }
  }
  locateDirs(argv[0]);
  if (Status st = g_params.read(config); !st) {
    std::cerr << "hermes_bench_server: " << st.error() << "\n";
    return 2;
  }
  if (!config.unusedKeys().empty()) {
    std::cerr << "hermes_bench_server: unknown key " << config.unusedKeys().front() << "\n";
    return 2;
  }
  nlohmann::json out;
  out["bench"] = "server";
  out["runs"] = nlohmann::json::array();
  for (int n : counts) {
    if (n < 1) {
      std::cerr << "hermes_bench_server: agent count must be >= 1\n";
      return 2;
    }
    auto r = acks_interval_ms > 0 ? runAcks(n, keypoints, acks_interval_ms) : run(n, keypoints);
    if (!r) {
      std::cerr << "hermes_bench_server: " << r.error() << "\n";
      return 1;
    }
    out["runs"].push_back(*r);
  }
  const std::string text = out.dump(2);
  std::cout << text << std::endl;
  if (!json_path.empty()) std::ofstream(json_path) << text << "\n";
  return 0;
}
