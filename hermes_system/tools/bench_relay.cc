// hermes_bench_relay (`./hermes bench relay`): the paper's outdoor relay
// scenario in small (§VII-B). Two ground robots reach the edge server over
// 4G-like links with outages; two aerial robots never reach the server and
// reach one ground robot each, intermittently (config/scenarios/relay_outdoor).
// The robots are time windows of the whole-sequence renders of the hall
// (dataset_window.h; without them, those windows rendered once into a cache):
// ground_1 = MH_01 0..D s, ground_2 = MH_02 0..D s, aerial_1 = MH_03 0..D s,
// aerial_2 = MH_01 20..20+D s. The same scenario runs
// twice, relaying on and off; prints a table on stderr and writes
//   {"with_relay": METRICS, "without_relay": METRICS, "min_relayed_mbitps": X, ...}
// (METRICS: metrics.json of DESIGN §7 with its "relay" block) on stdout or --json.
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <iterator>
#include <map>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

#include <unistd.h>

#include <nlohmann/json.hpp>

#include "bench_args.h"
#include "hermes/core/render/settings.h"
#include "hermes/core/render_cache.h"
#include "hermes/system/dataset_window.h"
#include "hermes/system/offline_run.h"
#include "hermes/system/run_results.h"
#include "hermes/system/scenario.h"
#include "hermes_help/hermes_bench_relay.h"  // tools/help/hermes_bench_relay.txt

using namespace hermes;
namespace fs = std::filesystem;

namespace {

const char* const kUsage = hermes_help::kText;

struct Robot {
  const char* name;
  const char* sequence;
  double start_s;
};
const Robot kRobots[] = {{"ground_1", "MH_01_easy", 0},
                         {"ground_2", "MH_02_easy", 0},
                         {"aerial_1", "MH_03_medium", 0},
                         {"aerial_2", "MH_01_easy", 20}};

Expected<nlohmann::json> runOnce(bool relay, const std::string& views, const std::string& scenario,
                                 std::vector<std::string> sets, std::string* report) {
  sets.push_back("link.scenario=" + scenario);
  sets.push_back(std::string("relay.enabled=") + (relay ? "true" : "false"));
  sets.push_back("uplink.buffer.fsync=false");
  auto config = loadConfig("", sets);
  if (!config) return Error{config.error()};
  auto params = system::readSystemParams(*config);
  if (!params) return Error{params.error()};
  std::vector<system::AgentSource> sources;
  for (const Robot& r : kRobots) {
    auto ds = Dataset::open((fs::path(views) / r.name).string(), params->run.dataset);
    if (!ds) return Error{ds.error()};
    sources.push_back({r.name, std::move(*ds), 0});
  }
  const std::string spool = (fs::temp_directory_path() /
                             ("hermes_bench_relay_spool_" + std::to_string(::getpid()))).string();
  auto run = system::OfflineRun::create(*params, std::move(sources), spool, HERMES_SOURCE_DIR);
  if (!run) return Error{run.error()};
  const char* label = relay ? "with relay" : "without relay";
  const auto t0 = std::chrono::steady_clock::now();
  double next_report = 0;
  Status s = (*run)->run([&](const system::ProgressInfo& p) {
    if (p.sim_time < next_report) return;
    next_report = p.sim_time + 5.0;
    std::fprintf(stderr, "[bench relay] %s: t %.0f/%.0f s%s, frames %zu/%zu, %d submaps merged, %d robots merged\n",
                 label, p.sim_time, p.sim_end, p.draining ? " (draining)" : "", p.frames_done,
                 p.frames_total, p.merged_submaps, p.agents_merged);
  });
  if (!s) return Error{s.error()};
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const system::RunResults r = system::evaluateRun(**run);
  *report = system::formatReport(**run, r);
  run->reset();  // its spools closed: then removed
  std::error_code ec;
  fs::remove_all(spool, ec);
  nlohmann::json j = system::resultsJson(r);
  j["wall_s"] = wall;
  return j;
}

}  // namespace

int main(int argc, char** argv) {
  double duration = 20;
  std::string data = std::string(HERMES_SOURCE_DIR) + "/data_cache/mh_full";
  std::string cache = std::string(HERMES_SOURCE_DIR) + "/data_cache/bench_relay";
  std::string scenario = std::string(HERMES_SOURCE_DIR) + "/config/scenarios/relay_outdoor/scenario.txt";
  std::string json_out;
  std::vector<std::string> sets;
  hermes::system::bench::Options opt(argc, argv, "hermes_bench_relay");
  while (opt.next()) {
    if (opt.is("--help") || opt.is("-h")) {
      std::printf("%s", kUsage);
      return 0;
    } else if (opt.is("--duration")) {
      duration = opt.number(1e-3, 60);
    } else if (opt.is("--data")) {
      data = opt.value();
    } else if (opt.is("--cache")) {
      cache = opt.value();
    } else if (opt.is("--scenario")) {
      scenario = opt.value();
    } else if (opt.is("--set")) {
      sets.push_back(opt.value());
    } else if (opt.is("--json")) {
      json_out = opt.value();
    } else {
      return opt.unknown();
    }
  }
  if (!(duration > 0 && duration <= 60))
    return std::fprintf(stderr, "hermes_bench_relay: --duration must be in (0, 60] s\n"), 2;
  if (!fs::exists(scenario))
    return std::fprintf(stderr, "hermes_bench_relay: scenario file '%s' does not exist\n", scenario.c_str()), 2;

  {  // bad input before any rendering: the overrides and the scenario
    auto config = loadConfig("", sets);
    auto params = config ? system::readSystemParams(*config) : Expected<system::SystemParams>(Error{config.error()});
    if (!params) return std::fprintf(stderr, "hermes_bench_relay: %s\n", params.error().c_str()), 2;
    std::vector<std::string> names;
    for (const Robot& r : kRobots) names.push_back(r.name);
    auto sc = system::Scenario::fromFile(scenario, names);
    if (!sc) return std::fprintf(stderr, "hermes_bench_relay: %s\n", sc.error().c_str()), 2;
  }
  const double rate = 20;
  const std::vector<std::string> seqs = {"MH_01_easy", "MH_02_easy", "MH_03_medium"};
  bool whole = true;
  for (const std::string& q : seqs) whole = whole && fs::exists(fs::path(data) / q / "mav0");
  // Where each robot's sequence lives, by its start: windows of the whole
  // renders, or (without them) just the robots' windows rendered once into the cache.
  std::map<double, fs::path> source;
  if (whole) {
    std::fprintf(stderr, "[bench relay] robots are windows of the whole renders in %s\n", data.c_str());
    for (const Robot& r : kRobots) source[r.start_s] = data;
  } else {
    std::fprintf(stderr, "[bench relay] no whole renders in %s: rendering the robots' %g-s windows into %s "
                         "(once; minutes)\n", data.c_str(), duration, cache.c_str());
    for (const Robot& r : kRobots) {
      if (source.count(r.start_s)) continue;
      RenderRequest req;
      for (const std::string& q : seqs)
        req.trajectories.push_back(std::string(HERMES_SOURCE_DIR) + "/config/trajectories/" + q + ".txt");
      req.start_s = r.start_s;
      req.duration_s = duration;
      req.rate_hz = rate;
      req.settings = {render::kPlainLook};  // the look of its published figures
      char key[64];
      std::snprintf(key, sizeof key, "d%g_s%g", duration, r.start_s);
      const fs::path folder = fs::path(cache) / key;
      if (Status st = renderCached(req, folder.string()); !st)
        return std::fprintf(stderr, "hermes_bench_relay: %s\n", st.error().c_str()), 1;
      source[r.start_s] = folder;
    }
  }
  const std::string views =
      (fs::temp_directory_path() / ("hermes_bench_relay_views_" + std::to_string(::getpid()))).string();
  for (const Robot& r : kRobots) {
    auto w = system::writeEurocWindow((source[r.start_s] / r.sequence).string(), whole ? r.start_s : 0.0,
                                      duration, (fs::path(views) / r.name).string());
    if (!w) return std::fprintf(stderr, "hermes_bench_relay: %s: %s\n", r.name, w.error().c_str()), 1;
  }

  nlohmann::json out = {{"bench", "relay"}, {"scenario", scenario}, {"duration_s", duration}};
  nlohmann::json robots = nlohmann::json::array();
  for (const Robot& r : kRobots)
    robots.push_back({{"agent", r.name}, {"sequence", r.sequence}, {"start_s", r.start_s}});
  out["robots"] = robots;
  for (bool relay : {true, false}) {
    std::string report;
    auto j = runOnce(relay, views, scenario, sets, &report);
    if (!j) {
      fs::remove_all(views);
      return std::fprintf(stderr, "hermes_bench_relay: %s\n", j.error().c_str()), 1;
    }
    std::fprintf(stderr, "---- %s ----\n%s", relay ? "with relay" : "without relay", report.c_str());
    out[relay ? "with_relay" : "without_relay"] = *j;
  }
  fs::remove_all(views);
  const nlohmann::json& relayed = out["with_relay"]["relay"]["min_relayed_mbitps"];
  out["min_relayed_mbitps"] = relayed;
  // Per robot side by side: merged or not, its own rate and what it forwarded.
  nlohmann::json table = nlohmann::json::array();
  std::fprintf(stderr, "%-10s | %-28s | %-28s\n", "robot", "with relay: merged ATE, own/relayed kB/s",
               "without: merged ATE, own kB/s");
  for (std::size_t i = 0; i < std::size(kRobots); ++i) {
    nlohmann::json row = {{"agent", kRobots[i].name}};
    std::string cells[2];
    for (int k = 0; k < 2; ++k) {
      const nlohmann::json& m = out[k == 0 ? "with_relay" : "without_relay"];
      const nlohmann::json& rr = m["relay"]["robots"][i];
      const nlohmann::json ate = m["per_agent"][i].value("merged_ate_rmse_m", nlohmann::json());
      const std::string key = k == 0 ? "with_relay" : "without_relay";
      row[key] = {{"merged_ate_m", ate}, {"own_kBps", rr["own_kBps"]}, {"relayed_kBps", rr["relayed_kBps"]},
                  {"exactly_once", rr["exactly_once"]}};
      char buf[96];
      char ate_text[32] = "unmerged";
      if (ate.is_number()) std::snprintf(ate_text, sizeof ate_text, "%.2f cm", ate.get<double>() * 100);
      std::snprintf(buf, sizeof buf, "%-9s %6.1f / %5.1f", ate_text, rr["own_kBps"].get<double>(),
                    rr["relayed_kBps"].get<double>());
      cells[k] = buf;
    }
    std::fprintf(stderr, "%-10s | %-28s | %-28s\n", kRobots[i].name, cells[0].c_str(), cells[1].c_str());
    table.push_back(row);
  }
  out["per_robot"] = table;
  const std::string text = out.dump(2) + "\n";
  if (json_out.empty()) {
    std::cout << text;
  } else {
    std::ofstream f(json_out);
    if (!(f << text)) return std::fprintf(stderr, "hermes_bench_relay: cannot write %s\n", json_out.c_str()), 1;
    std::fprintf(stderr, "[bench relay] wrote %s\n", json_out.c_str());
  }
  return 0;
}
