// hermes_bench_soak (`./hermes bench soak`): the server over a long mission
// (issue 20): a swarm flying its sequences again and again in waves (mission.h)
// over a link trace with losses, outages and dips, with a server crash and a
// robot crash, on the simulated clock. Samples the server's health
// (system.health_period_s: state bytes, resident memory, queue, time per
// submap) and writes the run's outputs, a summary JSON and plots
// (scripts/plot_soak.py): memory, latency and ATE over time.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

#include <nlohmann/json.hpp>

#include "bench_args.h"
#include "hermes/agent/run_config.h"
#include "hermes/core/render/settings.h"
#include "hermes/system/dataset_window.h"
#include "hermes/system/mission.h"
#include "hermes/system/offline_run.h"
#include "hermes/system/run_results.h"
#include "hermes/system/tracking_record.h"
#include "hermes_help/hermes_bench_soak.h"  // tools/help/hermes_bench_soak.txt

using namespace hermes;
namespace fs = std::filesystem;

using hermes::system::bench::groundTruthDir;
using hermes::system::bench::split;

namespace {

const char* const kUsage = hermes_help::kText;

/// The default soak link: `rate` Mbit/s, 30 ms, 1 % loss; an outage of 20 s
/// every 600 s (from 300 s) and 60 s at a fifth of the rate every 900 s (from 450 s).
std::string soakTrace(double rate, double end_s) {
  struct Row {
    double t, rate, loss;
  };
  std::vector<Row> rows{{0, rate, 0.01}};
  for (double t = 300; t < end_s; t += 600) rows.push_back({t, 0, 0.01}), rows.push_back({t + 20, rate, 0.01});
  for (double t = 450; t < end_s; t += 900) rows.push_back({t, rate / 5, 0.01}), rows.push_back({t + 60, rate, 0.01});
  std::stable_sort(rows.begin(), rows.end(), [](const Row& a, const Row& b) { return a.t < b.t; });
  std::ostringstream o;
  o << "time_s,rate_mbitps,latency_ms,loss\n";
  for (const Row& r : rows) o << r.t << ',' << r.rate << ",30," << r.loss << '\n';
  return o.str();
}

/// Summary of the health samples in [t0, t1): peaks and the last sample.
nlohmann::json healthSpan(const std::vector<system::HealthSample>& h, double t0, double t1) {
  nlohmann::json j;
  std::vector<double> p95;
  std::size_t rss_peak = 0, pending_peak = 0;
  const system::HealthSample* last = nullptr;
  for (const system::HealthSample& s : h) {
    if (s.time_s < t0 || s.time_s >= t1) continue;
    if (s.submaps > 0) p95.push_back(s.submap_ms_p95);
    rss_peak = std::max(rss_peak, s.rss_bytes);
    pending_peak = std::max(pending_peak, s.pending);
    if (s.server_up) last = &s;
  }
  j["from_s"] = t0;
  j["to_s"] = t1;
  j["rss_peak_mb"] = rss_peak / 1e6;
  j["pending_peak"] = pending_peak;
  j["submap_ms_p95_worst_sample"] = p95.empty() ? 0.0 : *std::max_element(p95.begin(), p95.end());
  if (last) {
    j["state_mb_end"] = last->state_bytes / 1e6;
    j["keyframes_end"] = last->keyframes;
    j["landmarks_end"] = last->landmarks;
    j["state_bytes_per_keyframe_end"] = last->keyframes ? double(last->state_bytes) / last->keyframes : 0.0;
  }
  return j;
}

int fail(const std::string& msg) {
  std::fprintf(stderr, "hermes_bench_soak: %s\n", msg.c_str());
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  system::MissionPlan plan;
  plan.sequences = split(hermes::system::bench::kMachineHall);
  std::string data = std::string(HERMES_SOURCE_DIR) + "/data_cache/mh_full";
  std::string tracking_dir, trace, out, json_out, robot_restart;
  double bandwidth = 10, server_restart_at = 90, health_period = 30;
  bool crash_sortie_live = false;
  std::vector<std::string> overrides;
  hermes::system::bench::Options opt(argc, argv, "hermes_bench_soak");
  while (opt.next()) {
    if (opt.is("--help") || opt.is("-h")) {
      std::cout << kUsage;
      return 0;
    } else if (opt.is("--robots")) {
      plan.robots = opt.whole(1, 1000);
    } else if (opt.is("--duration")) {
      plan.duration_s = opt.number(1);
    } else if (opt.is("--waves")) {
      plan.waves = opt.whole(1, 1000);
    } else if (opt.is("--sorties")) {
      plan.sorties = opt.whole(1, 1000);
    } else if (opt.is("--stagger")) {
      plan.stagger_s = opt.number(0);
    } else if (opt.is("--sequences")) {
      plan.sequences = split(opt.value());
    } else if (opt.is("--data")) {
      data = opt.value();
    } else if (opt.is("--tracking-dir")) {
      tracking_dir = opt.value();
    } else if (opt.is("--bandwidth")) {
      bandwidth = opt.number(1e-3);
    } else if (opt.is("--trace")) {
      trace = opt.value();
    } else if (opt.is("--server-restart-at")) {
      server_restart_at = opt.number();
    } else if (opt.is("--robot-restart")) {
      robot_restart = opt.value();
    } else if (opt.is("--crash-sortie-live")) {
      crash_sortie_live = true;
    } else if (opt.is("--health-period")) {
      health_period = opt.number(1e-3);
    } else if (opt.is("--set")) {
      overrides.push_back(opt.value());
    } else if (opt.is("--out")) {
      out = opt.value();
    } else if (opt.is("--json")) {
      json_out = opt.value();
    } else {
      return opt.unknown();
    }
  }
  if (out.empty()) return std::fprintf(stderr, "hermes_bench_soak: --out DIR is required\n%s", kUsage), 2;
  if (!(bandwidth > 0)) return fail("--bandwidth must be > 0 Mbit/s");
  if (!(health_period > 0)) return fail("--health-period must be > 0 s");
  if (!trace.empty() && !fs::exists(trace)) return fail("--trace " + trace + " does not exist");
  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec) return fail("cannot create " + out + ": " + ec.message());
  if (Status s = system::ensureWholeRenders(data, plan.sequences, groundTruthDir(), 20, {render::kPlainLook}); !s) return fail(s.error());

  // The plan: each sequence's length from its render.
  std::map<std::string, std::unique_ptr<Dataset>> bases;
  for (const std::string& seq : plan.sequences) {
    auto ds = Dataset::open((fs::path(data) / seq).string());
    if (!ds) return fail(ds.error());
    bases[seq] = std::move(*ds);
  }
  auto robots = system::planMission(plan, [&](const std::string& seq) {
    const Dataset& d = *bases.at(seq);
    return d.frameTime(d.size() - 1) - d.frameTime(0);
  });
  if (!robots) return fail(robots.error());
  double last_takeoff = 0;
  for (const auto& r : *robots) last_takeoff = std::max(last_takeoff, r.takeoffs_s.back());
  if (robot_restart.empty()) {  // r03, 40 s into its last sortie
    const auto& r = (*robots)[std::min<std::size_t>(2, robots->size() - 1)];
    robot_restart = r.name + "@" + std::to_string(r.takeoffs_s.back() + 40);
  }

  // Config: the link trace, the crashes, health samples.
  const double mission_end = last_takeoff + 200;
  if (trace.empty()) {
    trace = (fs::path(out) / "link_trace.csv").string();
    std::ofstream t(trace);
    t << soakTrace(bandwidth, mission_end);
    if (!t) return fail("cannot write " + trace);
  }
  std::vector<std::string> sets = overrides;
  sets.push_back("link.trace=" + fs::absolute(trace).string());
  sets.push_back("uplink.buffer.fsync=false");
  sets.push_back("system.health_period_s=" + std::to_string(health_period));
  if (server_restart_at >= 0) sets.push_back("system.server_restart_at=[" + std::to_string(server_restart_at) + "]");
  if (robot_restart != "none") sets.push_back("system.agent_reset=" + robot_restart);
  auto config = loadConfig("", sets);
  if (!config) return fail(config.error());
  auto params = system::readSystemParams(*config);
  if (!params) return fail(params.error());

  // Each robot's data on the mission clock, its sorties replayed where a recording fits.
  const double epoch = 1.7e9;  // [s] the mission's first stamp (2023-11-14)
  const fs::path views = fs::path(out) / "mission_data";
  std::vector<system::AgentSource> sources;
  int replayed = 0, live = 0;  // sorties
  std::vector<std::string> notes;
  for (const system::MissionRobot& r : *robots) {
    auto view = system::writeMissionView((fs::path(data) / r.sequence).string(), r.takeoffs_s, epoch,
                                         (views / r.name).string());
    if (!view) return fail("robot " + r.name + ": " + view.error());
    auto ds = Dataset::open((views / r.name).string(), params->run.dataset);
    if (!ds) return fail(ds.error());
    system::AgentSource src{r.name, std::move(*ds), 0};
    src.clock_origin = epoch;
    const Dataset& base = *bases.at(r.sequence);
    const agent::TrackingKey key = system::trackingKey(*params, r.sequence, base, base.size());
    const std::string rec = tracking_dir.empty() ? "" : system::trackingRecordPath(tracking_dir, r.sequence);
    Status fits = Error{"no --tracking-dir"};
    if (!rec.empty()) {
      auto recorded = agent::readTrackingKey(rec);
      fits = recorded ? recorded->matches(key) : Status(Error{recorded.error()});
      if (!fits) notes.push_back(r.name + ": " + rec + " does not fit (" + fits.error() + "): tracked from the images");
    }
    for (std::size_t s = 0; s < r.takeoffs_s.size(); ++s) {
      system::Sortie sortie;
      sortie.first_frame = view->first_frames[s];
      // A robot crash mid-sortie (system.agent_reset) goes on tracking a fresh
      // map from the images; the replay holds until then (--crash-sortie-live:
      // that sortie tracked from the images from its take-off).
      const double end = r.takeoffs_s[s] + (base.frameTime(base.size() - 1) - base.frameTime(0));
      const bool crashes = crash_sortie_live && std::any_of(params->clock.agent_reset.begin(),
                                                            params->clock.agent_reset.end(), [&](const auto& x) {
                                                              return x.agent == r.name && x.at_s >= r.takeoffs_s[s] &&
                                                                     x.at_s <= end;
                                                            });
      if (fits && !crashes) {
        sortie.replay_path = rec;
        sortie.replay_key = key;
        sortie.replay_shift_s = view->shifts_s[s];
        ++replayed;
      } else {
        ++live;
      }
      src.sorties.push_back(std::move(sortie));
    }
    sources.push_back(std::move(src));
  }
  for (const std::string& n : notes) std::fprintf(stderr, "hermes_bench_soak: %s\n", n.c_str());
  std::fprintf(stderr, "hermes_bench_soak: %zu robots x %d sorties in %d waves over %.0f s (last take-off %.0f s); %d sorties replayed, %d tracked from images\n",
               robots->size(), plan.sorties, plan.waves, plan.duration_s, last_takeoff, replayed, live);

  const std::string spool = (fs::temp_directory_path() / ("hermes_bench_soak_" + std::to_string(::getpid()))).string();
  auto run = system::OfflineRun::create(*params, std::move(sources), (fs::path(spool) / "spool").string(),
                                        HERMES_SOURCE_DIR);
  if (!run) return fail(run.error());
  const auto t0 = std::chrono::steady_clock::now();
  double last_print = -1e9;
  auto progress = [&](const system::ProgressInfo& p) {
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (wall - last_print < 30) return;
    last_print = wall;
    const auto& h = (*run)->health();
    std::fprintf(stderr, "  sim %6.0f/%.0f s  frames %zu/%zu  merged submaps %d  robots merged %d  state %.0f MB  wall %.0f s\n",
                 p.sim_time, p.sim_end, p.frames_done, p.frames_total, p.merged_submaps, p.agents_merged,
                 h.empty() ? 0.0 : h.back().state_bytes / 1e6, wall);
  };
  if (Status s = (*run)->run(progress); !s) return fail(s.error());
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const system::RunResults res = system::evaluateRun(**run);
  if (Status w = system::writeRunResults(**run, res, out); !w) return fail(w.error());
  {
    std::ofstream cfg(fs::path(out) / "config_used.yaml");
    cfg << params->yaml();
  }

  nlohmann::json j;
  j["bench"] = "soak";
  j["robots"] = robots->size();
  j["sorties_per_robot"] = plan.sorties;
  j["waves"] = plan.waves;
  j["mission_s"] = plan.duration_s;
  j["sim_end_s"] = (*run)->simTime();
  j["sorties_replayed"] = replayed;
  j["sorties_live"] = live;
  j["wall_s"] = wall;
  j["link_trace"] = trace;
  nlohmann::json m = system::resultsJson(res);
  for (const char* k : {"agents_merged", "ate_rmse_m", "bytes_total", "kBps_mean", "kBps_peak", "loops_accepted",
                        "loops_rejected", "loop_accuracy", "relocalised", "robots_new", "server_restarts",
                        "server_durability", "per_agent", "warnings"})
    if (m.contains(k)) j[k] = m[k];
  j["lost_messages"] = (*run)->lostMessages();
  std::size_t takeoffs = 0, crashes = 0, lost_landed = 0;
  for (const system::OfflineAgent& a : (*run)->agents()) {
    for (const system::AgentResetRecord& r : a.resets) (r.takeoff ? takeoffs : crashes) += 1;
    lost_landed += a.windows_lost_landed;
  }
  j["takeoffs"] = takeoffs;
  j["robot_crashes"] = crashes;
  j["windows_lost_at_takeoff"] = lost_landed;
  // Health per wave (from one wave's start to the next's) and over the whole run.
  const auto& h = (*run)->health();
  nlohmann::json waves = nlohmann::json::array();
  const double wave = plan.duration_s / plan.waves;
  for (int w = 0; w < plan.waves; ++w)
    waves.push_back(healthSpan(h, w * wave, w + 1 < plan.waves ? (w + 1) * wave : 1e18));
  j["health_per_wave"] = waves;
  nlohmann::json slow = nlohmann::json::array();  // what the slowest merges spent their time on
  for (const server::Server::MergeBreakdown& b : (*run)->server().slowestMerges())
    slow.push_back({{"t_s", b.now}, {"robot", b.robot}, {"seq", b.seq}, {"keyframes", b.keyframes},
                    {"loops_attempted", b.loops_attempted}, {"stage_ms", b.stage_ms}});
  j["server_slowest_merges"] = slow;
  j["health_all"] = healthSpan(h, -1, 1e18);
  const std::string soak_json = (fs::path(out) / "soak.json").string();
  {
    std::ofstream f(soak_json);
    f << j.dump(2) << '\n';
  }
  const std::string cmd = "/usr/bin/python3 '" + std::string(HERMES_SOURCE_DIR) + "/scripts/plot_soak.py' --run '" +
                          out + "' --out '" + (fs::path(out) / "plots").string() + "' >&2";
  if (std::system(cmd.c_str()) != 0) std::fprintf(stderr, "hermes_bench_soak: warning: plots failed (%s)\n", cmd.c_str());
  run->reset();
  fs::remove_all(spool, ec);
  if (json_out.empty()) {
    std::cout << j.dump(2) << '\n';
  } else {
    std::ofstream f(json_out);
    f << j.dump(2) << '\n';
    if (!f) return fail("cannot write " + json_out);
  }
  std::fprintf(stderr, "hermes_bench_soak: %s merged, ATE %.2f cm, %d loops, %zu take-offs, wall %.0f s; %s\n",
               m.value("agents_merged", 0) == static_cast<int>(robots->size()) ? "all" : "NOT all",
               m.value("ate_rmse_m", 0.0) * 100, m.value("loops_accepted", 0), takeoffs, wall, soak_json.c_str());
  return 0;
}
