// hermes_bench_system (`./hermes bench system`): the paper's system evaluations
// on rendered EuRoC-trajectory data (3 robots in one hall), all in-process on
// the simulated clock. For every (variant, shared bandwidth) pair: agents
// merged, merged ATE, bytes, kB/s, loops. Variants:
//   hermes        bandwidth-aware distillation (MILP + coordinator), CSA on, entropy keyframes
//   fixed_k100    no coordinator, K = 100 landmarks per keyframe (paper Fig. 16)
//   raw           no distillation: every keyframe and landmark (send-everything baseline)
//   csa_off       hermes with FIFO instead of the credibility queue (Fig. 17)
//   covisibility  hermes with covisibility keyframes instead of entropy (Fig. 14)
//   false_candidates  hermes with 20 % of place-recognition candidates replaced by
//                 random keyframes of other agents: PCM must keep every false loop out
// Prints a table on stderr and JSON on stdout (or --json FILE).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

#include <nlohmann/json.hpp>

#include "hermes/core/render_cache.h"
#include "hermes/system/dataset_window.h"
#include "hermes/system/offline_run.h"
#include "hermes/system/run_results.h"

using namespace hermes;
namespace fs = std::filesystem;

namespace {

const char* kUsage =
    "usage: hermes_bench_system [--duration S] [--rate HZ] [--cache DIR]\n"
    "                           [--bandwidths LIST] [--variants LIST] [--set KEY=VALUE]...\n"
    "                           [--json FILE]\n"
    "  --duration S     seconds rendered per robot (default 15)\n"
    "  --rate HZ        camera rate (default 20)\n"
    "  --cache DIR      rendered data cache (default data_cache/bench_system)\n"
    "  --bandwidths L   shared link rates in Mbit/s, 0 = unlimited (default 0,30,10,5,1,0.5)\n"
    "  --variants L     hermes,fixed_k100,raw,csa_off,covisibility,false_candidates\n"
    "                   (default: all; the last three only at the two lowest bandwidths,\n"
    "                   false_candidates only unlimited)\n"
    "  --set KEY=VALUE  configuration override for every run (repeatable; e.g.\n"
    "                   distill.k_max=300); the variant's own settings win\n"
    "  --swarm L        instead: swarm sizes (e.g. 2,5,10,15,20) sharing one\n"
    "                   --swarm-bandwidth link (default 50 Mbit/s, paper Fig. 18); robot k\n"
    "                   flies --duration s of sequence k mod S (of --swarm-sequences) from\n"
    "                   start 20 * (k / S) s: time windows of whole-sequence renders in\n"
    "                   one hall; variants default to hermes,raw\n"
    "  --swarm-bandwidth M  shared link of the swarm sweep [Mbit/s] (default 50)\n"
    "  --swarm-data DIR     whole-sequence renders (default data_cache/mh_full; rendered\n"
    "                   from ../shared/data/euroc_gt when a sequence is missing)\n"
    "  --swarm-sequences L  (default MH_01_easy,MH_02_easy,MH_03_medium,MH_04_difficult,\n"
    "                   MH_05_difficult)\n"
    "  --run-out DIR    also write each run's outputs as `hermes run` does (metrics.json,\n"
    "                   loops.csv, loop_attempts.csv but for false_candidates, ...) to\n"
    "                   DIR/<variant>_<robots>\n"
    "Prints JSON {runs: [...]} on stdout (or to --json FILE) and a table on stderr.\n";

std::vector<std::string> split(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  for (std::string item; std::getline(ss, item, ',');)
    if (!item.empty()) out.push_back(item);
  return out;
}

const char* kSeqs[] = {"MH_01_easy", "MH_02_easy", "MH_03_medium"};

std::vector<std::string> variantSets(const std::string& v) {
  if (v == "hermes") return {};
  if (v == "fixed_k100") return {"distill.coordinator=off", "distill.fixed_k=100"};
  if (v == "raw") return {"distill.strategy=none"};
  if (v == "csa_off") return {"server.csa=off"};
  if (v == "covisibility") return {"keyframe.policy=covisibility"};
  if (v == "false_candidates") return {};
  return {"?"};
}

/// Replaces a `fraction` of the place candidates (seeded draw) by a random keyframe
/// of another agent: what a poor place recogniser would propose.
void injectFalseCandidates(system::OfflineRun& run, double fraction, std::size_t* injected) {
  auto rng = std::make_shared<std::mt19937_64>(7);
  run.onServerCreated([rng, fraction, injected](server::Server& srv) {  // again after a restart
    server::MapManager& mm = srv.mapManager();
    mm.setCandidateHook([&mm, rng, fraction, injected](const KeyframeKey& query,
                                                       std::vector<PlaceCandidate>* c) {
      std::uniform_real_distribution<double> u(0, 1);
      for (PlaceCandidate& cand : *c) {
        if (u(*rng) >= fraction) continue;
        std::vector<KeyframeKey> others;
        for (const auto& [id, traj] : mm.map().trajectories)
          if (traj.agent != query.agent)
            for (const auto& [kid, kf] : traj.keyframes) others.push_back({traj.agent, traj.session, kid});
        if (others.empty()) continue;
        cand.key = others[std::uniform_int_distribution<std::size_t>(0, others.size() - 1)(*rng)];
        ++*injected;
      }
    });
  });
}

double loadAverage() {
  std::ifstream f("/proc/loadavg");
  double l = -1;
  f >> l;
  return l;
}

using Robots = std::vector<std::pair<std::string, fs::path>>;  // name, dataset folder

/// The three hall robots rendered from `start` seconds of their trajectories
/// (cached under cache/d<duration>_r<rate>[_s<start>]). One scene for every
/// start: hermes_sim builds it around the whole trajectories.
Expected<fs::path> renderCached(const std::string& cache, double duration, double rate, double start) {
  char key[96];
  if (start > 0)
    std::snprintf(key, sizeof key, "d%g_r%g_s%g", duration, rate, start);
  else
    std::snprintf(key, sizeof key, "d%g_r%g", duration, rate);
  RenderRequest req;
  for (const char* s : kSeqs)
    req.trajectories.push_back(std::string(HERMES_SOURCE_DIR) + "/config/trajectories/" + s + ".txt");
  req.start_s = start;
  req.duration_s = duration;
  req.rate_hz = rate;
  const fs::path data = fs::path(cache) / key;
  if (Status s = hermes::renderCached(req, data.string()); !s) return Error{s.error()};
  return data;
}

/// Swarm of n robots: robot k flies `duration` s of sequence k mod S from
/// start 20 * (k / S) s, a window view (dataset_window.h) of the whole-sequence
/// render in `data` (rendered there first when a sequence is missing), written
/// under `views`.
Expected<Robots> swarmRobots(const std::string& data, const std::vector<std::string>& seqs,
                             const std::string& views, double duration, double rate, int n) {
  if (Status s = system::ensureWholeRenders(data, seqs, std::string(HERMES_SHARED_DATA_DIR) + "/euroc_gt", rate); !s)
    return Error{s.error()};
  Robots robots;
  for (int k = 0; k < n; ++k) {
    const std::string& seq = seqs[k % seqs.size()];
    const int start = 20 * (k / static_cast<int>(seqs.size()));
    const std::string name = seq + (start ? "_s" + std::to_string(start) : "");
    const fs::path view = fs::path(views) / name;
    auto w = system::writeEurocWindow((fs::path(data) / seq).string(), start, duration, view.string());
    if (!w.ok()) return Error{w.error()};
    if (w->frames + 1 < duration * rate * 0.9)
      return Error{"swarm robot " + name + ": " + seq + " holds only " + std::to_string(w->frames) +
                   " frames from " + std::to_string(start) + " s (a smaller swarm or --duration)"};
    robots.push_back({name, view});
  }
  return robots;
}

/// One offline run of `variant` with all `robots` sharing a `bw` Mbit/s link.
Expected<nlohmann::json> runVariant(const std::string& v, const std::string& bw, const Robots& robots,
                                    const std::vector<std::string>& overrides,
                                    const std::string& run_out = "") {
  std::vector<std::string> sets = overrides;
  for (const std::string& s : variantSets(v)) sets.push_back(s);
  sets.push_back("link.bandwidth_mbitps=" + bw);
  sets.push_back("uplink.buffer.fsync=false");
  auto config = agent::loadRunConfig("", sets);
  if (!config.ok()) return Error{config.error()};
  auto params = system::readSystemParams(*config);
  if (!params.ok()) return Error{params.error()};
  std::vector<system::AgentSource> sources;
  for (const auto& [name, dir] : robots) {
    auto ds = Dataset::open(dir.string(), params->run.dataset);
    if (!ds.ok()) return Error{ds.error()};
    sources.push_back({name, std::move(*ds), 0});
  }
  // One spool per process: two benchmarks may run side by side.
  const std::string spool =
      (fs::temp_directory_path() / ("hermes_bench_system_spool_" + std::to_string(::getpid()))).string();
  auto run = system::OfflineRun::create(*params, std::move(sources), spool, HERMES_SOURCE_DIR);
  if (!run.ok()) return Error{run.error()};
  std::size_t injected = 0;
  if (v == "false_candidates") injectFalseCandidates(**run, 0.2, &injected);
  std::vector<server::LoopAttempt> attempts;
  if (!run_out.empty() && v != "false_candidates")  // that variant's hook holds the one slot
    (*run)->onServerCreated([&attempts](server::Server& srv) {
      srv.mapManager().setAttemptHook([&attempts](const server::LoopAttempt& a) { attempts.push_back(a); });
    });
  const auto t0 = std::chrono::steady_clock::now();
  if (Status s = (*run)->run(); !s) return Error{s.error()};
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const system::RunResults r = system::evaluateRun(**run);
  if (!run_out.empty()) {
    const fs::path out = fs::path(run_out) / (v + "_" + std::to_string(robots.size()));
    std::error_code mk;
    fs::create_directories(out, mk);
    if (Status w = system::writeRunResults(**run, r, out.string()); !w) return Error{w.error()};
    if (Status w = system::writeLoopAttempts(**run, attempts, (out / "loop_attempts.csv").string()); !w)
      return Error{w.error()};
  }
  nlohmann::json j = system::resultsJson(r);
  j["variant"] = v;
  j["agents"] = robots.size();
  j["bandwidth_mbitps"] = std::atof(bw.c_str());
  j["wall_s"] = wall;
  j["lost_messages"] = (*run)->lostMessages();
  // Server memory: its whole state as a checkpoint holds it (map, queue, loops,
  // graph), and the peak of what it held for robots awaiting merge.
  j["server_state_bytes"] = (*run)->server().saveState().size();
  std::int64_t held_peak = 0;
  for (const AgentMetrics& a : r.metrics.per_agent) held_peak += a.held_bytes_peak.value_or(0);
  j["server_held_bytes_peak_sum"] = held_peak;
  j["load_avg_1min"] = loadAverage();
  if (v == "false_candidates") j["injected_false_candidates"] = injected;
  double lost = 0;
  int n = 0;
  for (const AgentMetrics& a : r.metrics.per_agent)
    if (a.lost_rate) lost += *a.lost_rate, ++n;
  j["tracking_lost_rate_mean"] = n ? lost / n : 0.0;
  run->reset();
  std::error_code ec;
  fs::remove_all(spool, ec);  // the run's own files, not results
  return j;
}

double timing(const nlohmann::json& j, const char* stage, const char* stat) {
  if (!j.contains("timings_ms") || !j["timings_ms"].contains(stage)) return std::nan("");
  return j["timings_ms"][stage][stat].get<double>();
}

/// One row of the swarm table.
void printSwarmRow(const std::string& v, const nlohmann::json& j) {
  auto num = [&](const char* k) { return j.contains(k) && j[k].is_number() ? j[k].get<double>() : std::nan(""); };
  std::fprintf(stderr, "%-7s %3zu %4.0f/%-3zu %8.2f %9.0f %6.0f/%-6.0f %6.1f %8.0f %8.0f %9.1f %6.0f %5.2f\n",
               v.c_str(), j["agents"].get<std::size_t>(), num("agents_merged"), j["agents"].get<std::size_t>(),
               num("ate_rmse_m") * 100, num("bytes_total") / 1000.0, num("kBps_mean"), num("kBps_peak"),
               num("tracking_lost_rate_mean") * 100, timing(j, "submap", "median"), timing(j, "submap", "p95"),
               num("server_state_bytes") / 1e6, num("wall_s"), num("load_avg_1min"));
}

void printRow(const std::string& v, const std::string& bw, const nlohmann::json& j) {
  auto num = [&](const char* k) { return j.contains(k) && j[k].is_number() ? j[k].get<double>() : std::nan(""); };
  std::fprintf(stderr, "%-13s %9s %4.0f/%-2zu %10.2f %9.1f %9.1f %7.0f %8.1f\n", v.c_str(),
               std::atof(bw.c_str()) <= 0 ? "unlim" : bw.c_str(), num("agents_merged"),
               j["agents"].get<std::size_t>(), num("ate_rmse_m") * 100, num("bytes_total") / 1000.0,
               num("kBps_mean"), num("loops_accepted"), num("wall_s"));
}

int writeJson(const nlohmann::json& out, const std::string& path) {
  if (path.empty()) {
    std::cout << out.dump(2) << "\n";
    return 0;
  }
  std::ofstream f(path);
  f << out.dump(2) << "\n";
  if (!f) return std::fprintf(stderr, "cannot write %s\n", path.c_str()), 1;
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  double duration = 15, rate = 20;
  std::string cache = std::string(HERMES_SOURCE_DIR) + "/data_cache/bench_system";
  std::vector<std::string> bandwidths = split("0,30,10,5,1,0.5");
  std::vector<std::string> variants =
      split("hermes,fixed_k100,raw,csa_off,covisibility,false_candidates");
  std::string json_out;
  std::vector<std::string> swarm;
  std::string swarm_bw = "50";
  std::string run_out;
  std::string swarm_data = std::string(HERMES_SOURCE_DIR) + "/data_cache/mh_full";
  std::vector<std::string> swarm_seqs =
      split("MH_01_easy,MH_02_easy,MH_03_medium,MH_04_difficult,MH_05_difficult");
  std::vector<std::string> overrides;
  bool variants_given = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "hermes_bench_system: %s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--help" || a == "-h") {
      std::cout << kUsage;
      return 0;
    } else if (a == "--duration") {
      duration = std::atof(next().c_str());
    } else if (a == "--rate") {
      rate = std::atof(next().c_str());
    } else if (a == "--cache") {
      cache = next();
    } else if (a == "--bandwidths") {
      bandwidths = split(next());
    } else if (a == "--variants") {
      variants = split(next());
      variants_given = true;
    } else if (a == "--swarm") {
      swarm = split(next());
    } else if (a == "--swarm-bandwidth") {
      swarm_bw = next();
    } else if (a == "--run-out") {
      run_out = next();
    } else if (a == "--swarm-data") {
      swarm_data = next();
    } else if (a == "--swarm-sequences") {
      swarm_seqs = split(next());
    } else if (a == "--set") {
      overrides.push_back(next());
    } else if (a == "--json") {
      json_out = next();
    } else {
      std::fprintf(stderr, "hermes_bench_system: unknown argument '%s' (see --help)\n", a.c_str());
      return 2;
    }
  }
  if (!(duration > 0) || !(rate > 0)) {
    std::fprintf(stderr, "hermes_bench_system: --duration and --rate must be > 0\n");
    return 2;
  }
  for (const std::string& v : variants)
    if (variantSets(v) == std::vector<std::string>{"?"}) {
      std::fprintf(stderr, "hermes_bench_system: unknown variant '%s'\n", v.c_str());
      return 2;
    }

  if (!swarm.empty()) {
    if (!variants_given) variants = {"hermes", "raw"};
    for (const std::string& n : swarm)
      if (std::atoi(n.c_str()) < 1 || std::atoi(n.c_str()) > 40)
        return std::fprintf(stderr, "hermes_bench_system: swarm size '%s' not in 1..40\n", n.c_str()), 2;
    if (swarm_seqs.empty()) return std::fprintf(stderr, "hermes_bench_system: --swarm-sequences is empty\n"), 2;
  }
  if (!swarm.empty()) {
    nlohmann::json runs = nlohmann::json::array();
    const std::string views =
        (fs::temp_directory_path() / ("hermes_bench_swarm_views_" + std::to_string(::getpid()))).string();
    std::fprintf(stderr, "%-7s %3s %8s %8s %9s %13s %6s %8s %8s %9s %6s %5s\n", "variant", "n", "merged",
                 "ATE[cm]", "kB", "kB/s mean/pk", "lost%", "srv med", "srv p95", "state MB", "wall", "load");
    for (const std::string& n : swarm) {
      auto robots = swarmRobots(swarm_data, swarm_seqs, views, duration, rate, std::atoi(n.c_str()));
      if (!robots.ok()) return std::fprintf(stderr, "hermes_bench_system: %s\n", robots.error().c_str()), 1;
      for (const std::string& v : variants) {
        auto j = runVariant(v, swarm_bw, *robots, overrides, run_out);
        if (!j.ok()) return std::fprintf(stderr, "%s\n", j.error().c_str()), 1;
        printSwarmRow(v, *j);
        runs.push_back(*j);
        if (!json_out.empty())  // a long sweep keeps what it has
          (void)writeJson({{"bench", "system_swarm"}, {"partial", true}, {"runs", runs}}, json_out);
      }
    }
    std::error_code ec;
    fs::remove_all(views, ec);
    return writeJson({{"bench", "system_swarm"}, {"data", swarm_data}, {"sequences", swarm_seqs},
                      {"duration_s", duration}, {"rate_hz", rate},
                      {"bandwidth_mbitps", std::atof(swarm_bw.c_str())}, {"overrides", overrides},
                      {"runs", runs}},
                     json_out);
  }

  // Rendered data (cached).
  auto data = renderCached(cache, duration, rate, 0);
  if (!data.ok()) return std::fprintf(stderr, "hermes_bench_system: %s\n", data.error().c_str()), 1;
  Robots robots;
  for (const char* seq : kSeqs) robots.push_back({seq, *data / seq});

  // The two lowest bandwidths for the ablations.
  std::vector<std::string> low = bandwidths;
  std::sort(low.begin(), low.end(), [](const std::string& a, const std::string& b) {
    const double x = std::atof(a.c_str()), y = std::atof(b.c_str());
    return (x <= 0 ? 1e9 : x) < (y <= 0 ? 1e9 : y);
  });
  if (low.size() > 2) low.resize(2);

  nlohmann::json runs = nlohmann::json::array();
  std::fprintf(stderr, "%-13s %9s %7s %10s %9s %9s %7s %8s\n", "variant", "Mbit/s", "merged",
               "ATE [cm]", "kB", "kB/s", "loops", "wall [s]");
  for (const std::string& v : variants) {
    const bool ablation = v == "csa_off" || v == "covisibility";  // low bandwidths only
    for (const std::string& bw : bandwidths) {
      if (ablation && std::find(low.begin(), low.end(), bw) == low.end()) continue;
      if (v == "false_candidates" && std::atof(bw.c_str()) > 0) continue;
      auto j = runVariant(v, bw, robots, overrides);
      if (!j.ok()) return std::fprintf(stderr, "%s\n", j.error().c_str()), 1;
      printRow(v, bw, *j);
      runs.push_back(*j);
    }
  }
  return writeJson({{"bench", "system"},
                    {"data", data->string()},
                    {"duration_s", duration},
                    {"rate_hz", rate},
                    {"overrides", overrides},
                    {"runs", runs}},
                   json_out);
}
