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
//   md, md_a, md_b  hermes with one landmark selection at every K: the paper's MD
//                 (the MILP, also where the link binds), MD_A (stability) or MD_B
//                 (spatial ANMS) (landmark-scoring ablation; hermes itself uses the
//                 MILP at K = k_max and ANMS where the budget holds K lower)
// --full mh|v1: the whole-sequence table (bench_system_full.cc): five (three) robots
// over their whole sequences, each run kept in its own folder, resumable.
// Prints a table on stderr and JSON on stdout (or --json FILE).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <fstream>
#include <iostream>
#include <memory>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

#include <nlohmann/json.hpp>

#include "bench_args.h"
#include "cell_jobs.h"
#include "hermes/core/render/settings.h"
#include "hermes/core/render_cache.h"
#include "hermes/system/bench_store.h"
#include "hermes/system/dataset_window.h"
#include "hermes/system/offline_run.h"
#include "hermes/system/run_results.h"
#include "hermes/system/tracking_record.h"
#include "tracked_run.h"
#include "hermes_help/hermes_bench_system.h"  // tools/help/hermes_bench_system.txt

using namespace hermes;
namespace fs = std::filesystem;

using hermes::system::bench::groundTruthDir;
using hermes::system::bench::split;

namespace {

const char* const kUsage = hermes_help::kText;

const char* kSeqs[] = {"MH_01_easy", "MH_02_easy", "MH_03_medium"};

std::vector<std::string> variantSets(const std::string& v) {
  if (v == "hermes") return {};
  if (v == "fixed_k100") return {"distill.coordinator=off", "distill.fixed_k=100"};
  if (v == "raw") return {"distill.strategy=none"};
  if (v == "csa_off") return {"server.csa=off"};
  if (v == "covisibility") return {"keyframe.policy=covisibility"};
  if (v == "false_candidates") return {};
  if (v == "md") return {"distill.tight_strategy=same"};
  if (v == "md_a") return {"distill.strategy=stability", "distill.tight_strategy=same"};
  if (v == "md_b") return {"distill.strategy=anms", "distill.tight_strategy=same"};
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

using system::bench::Robots;

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
  req.settings = {render::kPlainLook};  // the look of the sweep's published figures
  const fs::path data = fs::path(cache) / key;
  if (Status s = hermes::renderCached(req, data.string()); !s) return Error{s.error()};
  return data;
}

/// Swarm of n robots: robot k flies `duration` s of sequence k mod S from
/// start first + 20 * (k / S) s, a window view (dataset_window.h) of the whole-sequence
/// render in `data` (rendered there first when a sequence is missing), written
/// under `views`.
Expected<Robots> swarmRobots(const std::string& data, const std::vector<std::string>& seqs,
                             const std::string& views, double duration, double rate, int n,
                             int first) {
  if (Status s = system::ensureWholeRenders(data, seqs, groundTruthDir(), rate, {render::kPlainLook}); !s)
    return Error{s.error()};
  Robots robots;
  for (int k = 0; k < n; ++k) {
    const std::string& seq = seqs[k % seqs.size()];
    const int start = first + 20 * (k / static_cast<int>(seqs.size()));
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
                                    const std::function<void(const system::ProgressInfo&)>& progress,
                                    const std::string& out_dir,
                                    const std::string& tracking_dir = "",
                                    std::string* tracking_mode = nullptr, bool record_only = false) {
  std::vector<std::string> sets = overrides;
  for (const std::string& s : variantSets(v)) sets.push_back(s);
  auto params = system::bench::benchParams(sets, bw);
  if (!params.ok()) return Error{params.error()};
  auto openSources = [&] { return system::bench::openRobots(robots, *params); };
  // Tracking: each robot whose recording in tracking_dir fits this run is
  // replayed, the others are tracked and recorded there (the first run of a
  // set, a robot corrupted, changed sequences or tracker settings).
  if (record_only && !tracking_dir.empty()) {  // a --jobs recorder with nothing to do
    auto sources = openSources();
    if (!sources) return Error{sources.error()};
    if (system::trackingRecordingsFit(*params, *sources, tracking_dir)) {
      if (tracking_mode) *tracking_mode = "replay";
      return nlohmann::json::object();
    }
  }
  // One spool per process: two benchmarks may run side by side.
  const std::string spool =
      (fs::temp_directory_path() / ("hermes_bench_system_spool_" + std::to_string(::getpid()))).string();
  std::string mode;
  auto run = system::bench::createTrackedRun(*params, openSources, tracking_dir, spool, v + "_" + bw, &mode);
  if (!run.ok()) return Error{run.error()};
  if (tracking_mode) *tracking_mode = mode;
  std::fprintf(stderr, "  %s_%s: tracking %s%s\n", v.c_str(), bw.c_str(), mode.c_str(),
               mode == "live" ? "" : (" (" + tracking_dir + ")").c_str());
  std::size_t injected = 0;
  if (v == "false_candidates") injectFalseCandidates(**run, 0.2, &injected);
  std::vector<server::LoopAttempt> attempts;
  if (!out_dir.empty() && v != "false_candidates")  // that variant's hook holds the one slot
    (*run)->onServerCreated([&attempts](server::Server& srv) {
      srv.mapManager().setAttemptHook([&attempts](const server::LoopAttempt& a) { attempts.push_back(a); });
    });
  const auto t0 = std::chrono::steady_clock::now();
  if (Status s = (*run)->run(progress); !s) return Error{s.error()};
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const system::RunResults r = system::evaluateRun(**run);
  if (!out_dir.empty()) {  // the run's own outputs, as `hermes run` writes them
    std::error_code mk;
    fs::create_directories(out_dir, mk);
    if (Status w = system::writeRunResults(**run, r, out_dir); !w) return Error{w.error()};
    const fs::path cfg_path = fs::path(out_dir) / "config_used.yaml";  // what bench pose_graph reads
    std::ofstream cfg(cfg_path);
    cfg << params->yaml();
    if (!cfg) return Error{"cannot write " + cfg_path.string()};
    if (v != "false_candidates")
      if (Status w = system::writeLoopAttempts(**run, attempts, (fs::path(out_dir) / "loop_attempts.csv").string()); !w)
        return Error{w.error()};
  }
  nlohmann::json j = system::resultsJson(r);
  j["variant"] = v;
  j["agents"] = robots.size();
  j["bandwidth_mbitps"] = std::atof(bw.c_str());
  j["wall_s"] = wall;
  j["tracking"] = mode;  // live | record | replay (same results; wall time differs)
  j["lost_messages"] = (*run)->lostMessages();
  // Server memory: its whole state as a checkpoint holds it (map, queue, loops,
  // graph), and the peak of what it held for robots awaiting merge.
  j["server_state_bytes"] = (*run)->server().saveState().size();
  std::int64_t held_peak = 0;
  for (const AgentMetrics& a : r.metrics.per_agent) held_peak += a.held_bytes_peak.value_or(0);
  j["server_held_bytes_peak_sum"] = held_peak;
  // What the slowest merges spent their time on (the p95 of "submap").
  nlohmann::json slow = nlohmann::json::array();
  for (const server::Server::MergeBreakdown& m : (*run)->server().slowestMerges())
    slow.push_back({{"t_s", m.now}, {"robot", m.robot}, {"seq", m.seq}, {"keyframes", m.keyframes},
                    {"loops_attempted", m.loops_attempted}, {"stage_ms", m.stage_ms}});
  j["server_slowest_merges"] = slow;
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

/// --full's options beside the variants and bandwidths.
struct FullOptions {
  std::string set;           ///< mh | v1
  std::string out;           ///< store folder (empty: results/bench_full_SET)
  std::string json_out;      ///< --json
  std::string tracking_dir;  ///< --tracking-dir (empty: OUT/tracking)
  bool live_tracking = false;
  std::string look;          ///< --realistic | --plain as given (empty: realistic)
  int jobs = 1;              ///< --jobs: runs at once, as child processes (cell_jobs.h)
  bool cell = false;         ///< --cell: a child of --jobs (one run; no table, JSON or plots)
  std::string record_robot;  ///< --record-robot: a child of --jobs recording this robot alone
  std::vector<std::string> argv;  ///< the command line, for the children

  /// Renders with every realism effect (render.realistic=true) unless --plain.
  bool realistic() const { return look != "--plain"; }
  double first_s = 0;        ///< --duration: each robot's first S seconds (0: whole)
};

/// The tracking folder of `variant`'s runs: a variant that changes the tracker
/// (keyframe.* / tracker.*) records its own, in a subfolder named after it.
std::string cellTrackingDir(const std::string& base, const std::string& variant) {
  if (base.empty()) return base;
  for (const std::string& s : variantSets(variant))
    if (s.rfind("keyframe.", 0) == 0 || s.rfind("tracker.", 0) == 0) return (fs::path(base) / variant).string();
  return base;
}

/// --full: the whole-sequence set `name` (mh | v1): render folder and sequences.
/// Realistic renders have their own folder (<set>_full_realistic).
Expected<std::pair<std::string, std::vector<std::string>>> fullSet(const std::string& name, bool realistic) {
  const std::string cache = std::string(HERMES_SOURCE_DIR) + "/data_cache/";
  const std::string suffix = realistic ? "_full_realistic" : "_full";
  if (name == "mh") return std::make_pair(cache + "mh" + suffix, split(hermes::system::bench::kMachineHall));
  if (name == "v1") return std::make_pair(cache + "v1" + suffix, split("V1_01_easy,V1_02_medium,V1_03_difficult"));
  return Error{"--full: unknown set '" + name + "' (mh or v1)"};
}

/// One row of the --full table: merged, ATE all and per robot (own odometry),
/// bytes, kB/s, loops, lost rate, server time per submap, wall.
void printFullRow(const std::string& v, const std::string& bw, const nlohmann::json& j, bool resumed) {
  auto num = [&](const nlohmann::json& o, const char* k) {
    return o.contains(k) && o[k].is_number() ? o[k].get<double>() : std::nan("");
  };
  std::string agents;
  for (const nlohmann::json& a : j.value("per_agent", nlohmann::json::array())) {
    char cell[48];
    std::snprintf(cell, sizeof cell, " %5.2f(%5.2f)", num(a, "merged_ate_rmse_m") * 100, num(a, "raw_ate_rmse_m") * 100);
    agents += cell;
  }
  const nlohmann::json la = j.value("loop_accuracy", nlohmann::json::object());
  char loops[48];
  std::snprintf(loops, sizeof loops, "%.0f/%.0f/%.0f", num(j, "loops_accepted"), num(j, "loops_rejected"),
                num(la, "wrong"));
  std::fprintf(stderr, "%-10s %6s %2.0f/%-2zu %6.2f %s %7.1f %5.0f/%-5.0f %15s %5.2f %6.0f/%-6.0f %6.0f%s\n",
               v.c_str(), std::atof(bw.c_str()) <= 0 ? "unlim" : bw.c_str(), num(j, "agents_merged"),
               j["agents"].get<std::size_t>(), num(j, "ate_rmse_m") * 100, agents.c_str(),
               num(j, "bytes_total") / 1e6, num(j, "kBps_mean"), num(j, "kBps_peak"), loops,
               num(j, "tracking_lost_rate_mean") * 100,
               timing(j, "submap", "median"), timing(j, "submap", "p95"), num(j, "wall_s"),
               resumed ? "  (kept from an earlier run)" : "");
}

/// --full: every (variant, bandwidth) over the whole sequences of `set`, each run
/// stored as it finishes (BenchStore), then the table, the combined JSON and plots.
int runFull(FullOptions o, std::vector<std::string> variants, std::vector<std::string> bandwidths,
            bool variants_given, bool bandwidths_given, double rate, const std::vector<std::string>& overrides) {
  const std::string& set = o.set;
  std::string& out = o.out;
  std::string& tracking_dir = o.tracking_dir;
  const double first_s = o.first_s;
  auto data = fullSet(set, o.realistic());
  if (!data.ok()) return std::fprintf(stderr, "hermes_bench_system: %s\n", data.error().c_str()), 2;
  if (!variants_given) variants = split("hermes,raw,fixed_k100");
  if (!bandwidths_given) bandwidths = split("0,10,2,0.5");
  if (out.empty())
    out = "results/bench_full_" + set + (o.realistic() ? "_realistic" : "");
  // The tracking is recorded by the first run and replayed by the others
  // (tracking_record.h): the agents' tracking is most of a run's time.
  if (o.live_tracking) tracking_dir.clear();
  else if (tracking_dir.empty()) tracking_dir = (fs::path(out) / "tracking").string();
  const auto& [dir, seqs] = *data;
  const std::vector<std::string> render_settings = {o.realistic() ? "render.realistic=true" : render::kPlainLook};
  if (Status s = system::ensureWholeRenders(dir, seqs, groundTruthDir(), rate, render_settings); !s)
    return std::fprintf(stderr, "hermes_bench_system: %s\n", s.error().c_str()), 1;
  Robots robots;
  for (const std::string& seq : seqs) {
    if (first_s <= 0) {
      robots.push_back({seq, fs::path(dir) / seq});
      continue;
    }
    const fs::path view = fs::path(out) / "views" / seq;  // --duration: the first S seconds
    // A --jobs child takes the view its parent wrote (its siblings read it).
    if (!(o.cell && fs::exists(view / "mav0" / "cam0" / "data.csv"))) {
      auto w = system::writeEurocWindow((fs::path(dir) / seq).string(), 0, first_s, view.string());
      if (!w.ok()) return std::fprintf(stderr, "hermes_bench_system: %s\n", w.error().c_str()), 1;
    }
    robots.push_back({seq, view});
  }
  const nlohmann::json setup = {{"bench", "system_full"}, {"set", set}, {"data", dir},
                                {"sequences", seqs}, {"rate_hz", rate}, {"first_s", first_s},
                                {"overrides", overrides}};  // "data" names the render folder
  auto store = system::BenchStore::open(out, setup);
  if (!store.ok()) return std::fprintf(stderr, "hermes_bench_system: %s\n", store.error().c_str()), 2;
  std::fprintf(stderr, "hermes_bench_system: --full %s: %zu robots, %zu runs, kept in %s\n", set.c_str(),
               robots.size(), variants.size() * bandwidths.size(), out.c_str());
  std::string header;
  for (const std::string& seq : seqs) header += " " + seq.substr(0, 5) + "(odom)";
  std::fprintf(stderr, "%-10s %6s %5s %6s%s %7s %11s %14s %5s %13s %6s\n", "variant", "Mbit/s", "merged", "ATE",
               header.c_str(), "MB", "kB/s mn/pk", "loops a/r/wrong", "lost%", "srv ms med/p95", "wall");
  if (!o.record_robot.empty()) {  // a --jobs recorder: this robot alone, no row
    Robots one;
    for (const auto& r : robots)
      if (r.first == o.record_robot) one.push_back(r);
    if (one.empty()) return std::fprintf(stderr, "hermes_bench_system: --record-robot: no robot '%s'\n", o.record_robot.c_str()), 2;
    std::string mode;
    const auto t0 = std::chrono::steady_clock::now();
    double last = 0;
    auto progress = [&](const system::ProgressInfo& p) {
      const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      if (wall - last < 60) return;
      last = wall;
      std::fprintf(stderr, "  [record %s] frames %zu/%zu  wall %.0f s\n", o.record_robot.c_str(), p.frames_done,
                   p.frames_total, wall);
    };
    auto j = runVariant(variants.front(), "0", one, overrides, progress, "",
                        cellTrackingDir(tracking_dir, variants.front()), &mode, true);
    if (!j.ok()) return std::fprintf(stderr, "hermes_bench_system: record %s: %s\n", o.record_robot.c_str(), j.error().c_str()), 1;
    std::fprintf(stderr, "  record %s: %s (%.0f s)\n", o.record_robot.c_str(), mode == "replay" ? "recording fits" : "recorded",
                 std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    return 0;
  }
  std::set<std::string> by_children;
  if (o.jobs > 1 && !o.cell) {  // the runs not stored yet, as child processes
    std::vector<system::bench::Cell> cells, recorders;
    std::set<std::string> dirs;
    for (const std::string& v : variants)
      for (const std::string& bw : bandwidths) {
        char name[64];
        std::snprintf(name, sizeof name, "%s_%g", v.c_str(), std::atof(bw.c_str()));
        if (store->find(name)) continue;
        const std::string td = cellTrackingDir(tracking_dir, v);
        cells.push_back({name, v, bw, td, ""});
        if (!td.empty() && dirs.insert(td).second)  // one recorder per robot and tracking folder
          for (const auto& r : robots)
            recorders.push_back({"record_" + r.first + (td == tracking_dir ? "" : "_" + v), v, "0", td, r.first});
      }
    // Longest first, so that the last runs to finish are short ones: raw streaming's
    // server is the slowest (25 min unlimited on whole MH against 2-10 for the others).
    std::stable_partition(cells.begin(), cells.end(), [](const system::bench::Cell& c) { return c.variant == "raw"; });
    cells.insert(cells.begin(), recorders.begin(), recorders.end());
    std::fprintf(stderr, "hermes_bench_system: %zu runs, %d at once\n", cells.size(), o.jobs);
    const std::vector<std::string> failed = system::bench::runCellsInChildren(cells, o.jobs, o.argv);
    for (const system::bench::Cell& c : cells) by_children.insert(c.name);
    if (!failed.empty()) {
      std::string list;
      for (const std::string& f : failed) list += " " + f;
      std::fprintf(stderr, "hermes_bench_system: runs failed:%s (the others are stored; run again to resume)\n",
                   list.c_str());
      return 1;
    }
  }
  nlohmann::json runs = nlohmann::json::array();
  std::size_t index = 0;
  const std::size_t total = variants.size() * bandwidths.size();
  for (const std::string& v : variants)
    for (const std::string& bw : bandwidths) {
      ++index;
      char name[64];
      std::snprintf(name, sizeof name, "%s_%g", v.c_str(), std::atof(bw.c_str()));
      if (auto row = store->find(name)) {
        printFullRow(v, bw, *row, !by_children.count(name));
        runs.push_back(*row);
        continue;
      }
      const auto t0 = std::chrono::steady_clock::now();
      double last = 0;
      std::string mode;
      auto progress = [&](const system::ProgressInfo& p) {
        const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        if (wall - last < 30) return;
        last = wall;
        std::fprintf(stderr, "  [%zu/%zu %s, tracking %s] sim %6.1f/%.1f s%s  frames %zu/%zu  agents merged %d/%zu  wall %.0f s\n",
                     index, total, name, mode.c_str(), p.sim_time, p.sim_end,
                     p.draining ? " (delivering backlog)" : "", p.frames_done, p.frames_total,
                     p.agents_merged, robots.size(), wall);
      };
      auto j = runVariant(v, bw, robots, overrides, progress, store->runDir(name),
                          cellTrackingDir(tracking_dir, v), &mode);
      if (!j.ok()) return std::fprintf(stderr, "hermes_bench_system: %s: %s\n", name, j.error().c_str()), 1;
      (*j)["run"] = name;
      if (Status s = store->save(name, *j); !s)
        return std::fprintf(stderr, "hermes_bench_system: %s\n", s.error().c_str()), 1;
      printFullRow(v, bw, *j, false);
      runs.push_back(*j);
    }
  if (o.cell) return 0;  // the parent writes the table
  nlohmann::json all = setup;
  all["runs"] = runs;
  const std::string combined = (fs::path(out) / "bench_system_full.json").string();
  if (writeJson(all, combined) != 0) return 1;
  const std::string script = std::string(HERMES_SOURCE_DIR) + "/scripts/plot_bench_full.py";
  const std::string cmd = "/usr/bin/python3 '" + script + "' --json '" + combined + "' --out '" +
                          (fs::path(out) / "plots").string() + "' >/dev/null 2>&1";
  if (std::system(cmd.c_str()) != 0)
    std::fprintf(stderr, "hermes_bench_system: warning: plots failed (%s)\n", cmd.c_str());
  std::fprintf(stderr, "hermes_bench_system: table in %s, plots in %s/plots\n", combined.c_str(), out.c_str());
  return o.json_out.empty() ? 0 : writeJson(all, o.json_out);
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
  int swarm_first = 20;
  std::vector<std::string> swarm_seqs =
      split(hermes::system::bench::kMachineHall);
  std::vector<std::string> overrides;
  FullOptions full;
  bool variants_given = false, bandwidths_given = false, duration_given = false;
  hermes::system::bench::Options opt(argc, argv, "hermes_bench_system");
  while (opt.next()) {
    if (opt.is("--help") || opt.is("-h")) {
      std::cout << kUsage;
      return 0;
    } else if (opt.is("--duration")) {
      duration = opt.number(1e-3);
      duration_given = true;
    } else if (opt.is("--rate")) {
      rate = opt.number(1e-3);
    } else if (opt.is("--cache")) {
      cache = opt.value();
    } else if (opt.is("--bandwidths")) {
      bandwidths = split(opt.value());
      bandwidths_given = true;
    } else if (opt.is("--variants")) {
      variants = split(opt.value());
      variants_given = true;
    } else if (opt.is("--swarm")) {
      swarm = split(opt.value());
    } else if (opt.is("--swarm-bandwidth")) {
      swarm_bw = opt.value();
    } else if (opt.is("--run-out")) {
      run_out = opt.value();
    } else if (opt.is("--swarm-data")) {
      swarm_data = opt.value();
    } else if (opt.is("--swarm-first")) {
      swarm_first = opt.whole(0, 1000);
    } else if (opt.is("--swarm-sequences")) {
      swarm_seqs = split(opt.value());
    } else if (opt.is("--full")) {
      full.set = opt.value();
    } else if (opt.is("--out")) {
      full.out = opt.value();
    } else if (opt.is("--live-tracking")) {
      full.live_tracking = true;
    } else if (opt.is("--tracking-dir")) {
      full.tracking_dir = opt.value();
    } else if (opt.is("--realistic") || opt.is("--plain")) {
      const std::string flag = opt.is("--plain") ? "--plain" : "--realistic";
      if (!full.look.empty() && full.look != flag)
        return std::fprintf(stderr, "hermes_bench_system: --realistic and --plain exclude each other\n"), 2;
      full.look = flag;
    } else if (opt.is("--jobs")) {
      full.jobs = static_cast<int>(opt.whole(1, 16));
    } else if (opt.is("--cell")) {
      full.cell = true;
    } else if (opt.is("--record-robot")) {
      full.record_robot = opt.value();
    } else if (opt.is("--set")) {
      overrides.push_back(opt.value());
    } else if (opt.is("--json")) {
      json_out = opt.value();
    } else {
      return opt.unknown();
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

  if (!full.set.empty() && !swarm.empty())
    return std::fprintf(stderr, "hermes_bench_system: --full and --swarm are two different tables; give one\n"), 2;
  if (!full.out.empty() && full.set.empty())
    return std::fprintf(stderr, "hermes_bench_system: --out is --full's store folder; give --full too\n"), 2;
  if ((full.live_tracking || !full.tracking_dir.empty() || !full.look.empty() || full.jobs > 1 || full.cell) &&
      full.set.empty())
    return std::fprintf(stderr, "hermes_bench_system: --live-tracking / --tracking-dir / --realistic / --plain / --jobs belong to --full\n"), 2;
  if (!run_out.empty() && swarm.empty())
    return std::fprintf(stderr, "hermes_bench_system: --run-out belongs to --swarm (--full keeps every run in --out)\n"), 2;
  if (!full.set.empty()) {
    full.argv.assign(argv, argv + argc);
    full.json_out = json_out;
    full.first_s = duration_given ? duration : 0;
    return runFull(full, variants, bandwidths, variants_given, bandwidths_given, rate, overrides);
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
      auto robots = swarmRobots(swarm_data, swarm_seqs, views, duration, rate, std::atoi(n.c_str()), swarm_first);
      if (!robots.ok()) return std::fprintf(stderr, "hermes_bench_system: %s\n", robots.error().c_str()), 1;
      for (const std::string& v : variants) {
        auto j = runVariant(v, swarm_bw, *robots, overrides, nullptr,
                            run_out.empty() ? "" : (fs::path(run_out) / (v + "_" + n)).string());
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
                      {"duration_s", duration}, {"rate_hz", rate}, {"first_s", swarm_first},
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
    const bool ablation = v == "csa_off" || v == "covisibility" || v == "md" || v == "md_a" || v == "md_b";  // low bandwidths only
    for (const std::string& bw : bandwidths) {
      if (ablation && std::find(low.begin(), low.end(), bw) == low.end()) continue;
      if (v == "false_candidates" && std::atof(bw.c_str()) > 0) continue;
      auto j = runVariant(v, bw, robots, overrides, nullptr, "");
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
