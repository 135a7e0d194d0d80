// hermes_bench_multisession (`./hermes bench multisession`): maps that outlive a
// mission (issue 47). On whole EuRoC Machine Hall renders (one hall):
//   mission 1: MH_01-03 fly; the server's final map is saved (saveMapToResume)
//   mission 2: MH_04 and MH_05 resumed on it (server.prior_map), and again
//              started empty
// each at every shared-link bandwidth asked for. Per mission-2 run: robots
// merged, merged ATE under its own alignment and (resumed) under mission 1's
// alignment — mission 2 drawn in the prior's world frame with no alignment of
// its own — whether that world frame is the prior's, and per robot the seconds
// from its first submap to its placement in the world frame (server clock),
// bytes up / down, sessions the borrowed map placed. Runs are kept one folder
// each (BenchStore): an interrupted benchmark resumes. The tracking of every
// robot is recorded once and replayed by the other runs (tracked_run.h).
// Then a robot lost mid-hall: MH_04 from 30 s on, on mission 1's map, its camera
// dark for 2 s at 12 s (blackOutFrames): with the downlink its new session is
// placed by the borrowed map; without it only by the server's next loop.
// Prints JSON on stdout (or --json FILE) and a table on stderr.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

#include <unistd.h>

#include <nlohmann/json.hpp>

#include "bench_args.h"
#include "hermes/core/evaluation.h"
#include "hermes/core/render/settings.h"
#include "hermes/server/server_outputs.h"
#include "hermes/system/bench_store.h"
#include "hermes/system/dataset_window.h"
#include "hermes/system/offline_run.h"
#include "hermes/system/run_results.h"
#include "hermes_help/hermes_bench_multisession.h"  // tools/help/hermes_bench_multisession.txt
#include "tracked_run.h"

using namespace hermes;
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

using system::bench::Robots;

struct Options {
  std::string out = "results/bench_multisession", json_out, tracking_dir;
  std::vector<std::string> bandwidths = {"0", "2"}, overrides;
  double duration = 0;  ///< each robot's first S seconds (0: whole)
  double lost_start_s = 30, lost_after_s = 12;  ///< the lost robot: MH_04 from, dark from (after its start)
  bool realistic = true;
};

/// Mission 1's alignment (its metrics' "alignment"), for mission 2 in its frame.
std::optional<eval::Alignment> alignmentOf(const json& row) {
  if (!row.contains("alignment") || !row["alignment"].contains("t_xyz")) return std::nullopt;
  const json& a = row["alignment"];
  eval::Alignment al;
  al.mode = eval::AlignMode::kSE3;
  const auto t = a["t_xyz"].get<std::vector<double>>();
  const auto q = a["q_xyzw"].get<std::vector<double>>();
  al.T_gt_est = SE3(Quat(q[3], q[0], q[1], q[2]).normalized(), Vec3(t[0], t[1], t[2]));
  al.scale = a.value("scale", 1.0);
  return al;
}

/// Merged ATE [m] of every robot of `run` under `alignment` (all poses pooled).
std::optional<double> ateUnder(const system::OfflineRun& run, const eval::Alignment& alignment) {
  eval::Association all;
  for (const system::OfflineAgent& a : run.agents()) {
    if (!a.robot) continue;
    const Trajectory est = server::agentTrajectory(run.server().map(), *a.robot, a.dataset->info().T_B_C);
    const Trajectory& gt = a.dataset->info().groundtruth;
    if (est.empty() || gt.empty()) continue;
    auto as = eval::associate(gt, est, run.params().run.eval.max_dt);
    if (!as.ok()) continue;
    all.t.insert(all.t.end(), as->t.begin(), as->t.end());
    all.gt.insert(all.gt.end(), as->gt.begin(), as->gt.end());
    all.est.insert(all.est.end(), as->est.begin(), as->est.end());
  }
  if (all.matched() == 0) return std::nullopt;
  return eval::ateWithAlignment(all, alignment).trans_m.rmse;
}

/// Per robot: placement in the world frame (server clock), bytes, sessions.
json perAgent(const system::OfflineRun& run, const system::RunResults& r, bool* new_world) {
  json out = json::array();
  for (const system::OfflineAgent& a : run.agents()) {
    json j = {{"agent", a.name}, {"placement_s", nullptr}, {"anchored_by", "none"}};
    if (a.robot)
      if (const AgentStats* st = run.server().bookkeeper().stats(*a.robot); st && !st->sessions.empty()) {
        const SessionStats& first = st->sessions.begin()->second;
        j["anchored_by"] = toString(first.anchored_by);
        if (first.anchored_at >= 0) j["placement_s"] = first.anchored_at - first.first_time;
        for (const auto& [id, s] : st->sessions)
          if (s.anchored_by == SessionAnchor::kWorld) *new_world = true;
      }
    for (const AgentMetrics& m : r.metrics.per_agent)
      if (m.agent == a.name) {
        j["bytes_up"] = m.bytes.value_or(0);
        j["bytes_down"] = m.downlink_bytes.value_or(0);
        j["borrowed_relocalisations"] = m.borrowed_relocalisations.value_or(0);
        j["borrowed_memory_bytes"] = m.borrowed_memory_bytes.value_or(0);
        j["merged_ate_rmse_m"] = m.merged_ate_rmse_m ? json(*m.merged_ate_rmse_m) : json(nullptr);
        j["raw_ate_rmse_m"] = m.raw_ate_rmse_m ? json(*m.raw_ate_rmse_m) : json(nullptr);
        j["global_pose_rmse_m"] = m.global_pose_rmse_m ? json(*m.global_pose_rmse_m) : json(nullptr);
      }
    json sessions = json::array();  // as the robot saw them (its own clock)
    for (const auto& p : a.pipeline->placements())
      sessions.push_back({{"session", p.session}, {"started_s", p.started},
                          {"placed_s", p.placed < 0 ? json(nullptr) : json(p.placed)},
                          {"by_borrowed", p.by_borrowed}});
    j["sessions"] = sessions;
    out.push_back(j);
  }
  return out;
}

/// One mission: `robots` over a shared `bw` Mbit/s link, `sets` on top of the
/// options' overrides; outputs (and the map to resume on) in `dir`.
Expected<json> runMission(const Options& o, const std::string& label, const Robots& robots, const std::string& bw,
                          std::vector<std::string> sets, const std::string& dir,
                          const std::optional<eval::Alignment>& prior_alignment) {
  sets.insert(sets.begin(), o.overrides.begin(), o.overrides.end());
  auto params = system::bench::benchParams(sets, bw);
  if (!params.ok()) return Error{params.error()};
  auto open = [&] { return system::bench::openRobots(robots, *params); };
  const std::string spool =
      (fs::temp_directory_path() / ("hermes_bench_multisession_spool_" + std::to_string(::getpid()))).string();
  std::string mode;
  auto run = system::bench::createTrackedRun(*params, open, o.tracking_dir, spool, label, &mode);
  if (!run.ok()) return Error{run.error()};
  const auto t0 = std::chrono::steady_clock::now();
  double last = 0;
  auto progress = [&](const system::ProgressInfo& p) {
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (wall - last < 30) return;
    last = wall;
    std::fprintf(stderr, "  [%s, tracking %s] sim %6.1f/%.1f s  frames %zu/%zu  merged %d/%zu  wall %.0f s\n",
                 label.c_str(), mode.c_str(), p.sim_time, p.sim_end, p.frames_done, p.frames_total,
                 p.agents_merged, robots.size(), wall);
  };
  if (Status s = (*run)->run(progress); !s) return Error{s.error()};
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const system::RunResults r = system::evaluateRun(**run);
  if (Status w = system::writeRunResults(**run, r, dir); !w) return Error{w.error()};
  if (Status w = system::saveMapToResume((*run)->server(), (fs::path(dir) / "map").string()); !w)
    return Error{w.error()};
  json j = system::resultsJson(r);
  bool new_world = false;
  j["per_agent"] = perAgent(**run, r, &new_world);
  const int prior_robots = (*run)->server().mapManager().priorAgents();
  j["prior_robots"] = prior_robots;
  j["world_frame_from_prior"] = prior_robots > 0 && !new_world;
  j["ate_in_prior_frame_m"] = nullptr;
  if (prior_alignment)
    if (auto ate = ateUnder(**run, *prior_alignment)) j["ate_in_prior_frame_m"] = *ate;
  const server::DownlinkParams& down = params->server.downlink;
  j["downlink_budget_bytes_per_robot"] =
      down.enabled ? down.bytes_per_s * ((*run)->simTime() + down.burst_s) : 0.0;
  j["sim_s"] = (*run)->simTime();
  j["bandwidth_mbitps"] = std::atof(bw.c_str());
  j["wall_s"] = wall;
  j["tracking"] = mode;
  run->reset();
  std::error_code ec;
  fs::remove_all(spool, ec);
  return j;
}

double num(const json& j, const char* k) { return j.contains(k) && j[k].is_number() ? j[k].get<double>() : std::nan(""); }

void printRow(const std::string& name, const json& j) {
  std::string agents;
  for (const json& a : j["per_agent"]) {
    char cell[96];
    std::snprintf(cell, sizeof cell, "  %s placed %5.1f s (%s) up %6.0f kB down %4.0f kB borrowed %lld",
                  a["agent"].get<std::string>().substr(0, 5).c_str(), num(a, "placement_s"),
                  a["anchored_by"].get<std::string>().c_str(), num(a, "bytes_up") / 1e3, num(a, "bytes_down") / 1e3,
                  static_cast<long long>(num(a, "borrowed_relocalisations")));
    agents += cell;
  }
  std::fprintf(stderr, "%-12s merged %2.0f  ATE %5.2f cm  in prior frame %5.2f cm  prior world %s%s\n", name.c_str(),
               num(j, "agents_merged"), num(j, "ate_rmse_m") * 100, num(j, "ate_in_prior_frame_m") * 100,
               j.value("world_frame_from_prior", false) ? "yes" : "no ", agents.c_str());
}

Expected<Robots> robotsOf(const Options& o, const std::string& data, const std::vector<std::string>& seqs) {
  Robots robots;
  for (const std::string& seq : seqs) {
    if (o.duration <= 0) {
      robots.push_back({seq, fs::path(data) / seq});
      continue;
    }
    const fs::path view = fs::path(o.out) / "views" / seq;  // the first S seconds
    auto w = system::writeEurocWindow((fs::path(data) / seq).string(), 0, o.duration, view.string());
    if (!w.ok()) return Error{w.error()};
    robots.push_back({seq, view});
  }
  return robots;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  system::bench::Options opt(argc, argv, "hermes_bench_multisession");
  while (opt.next()) {
    if (opt.is("--help") || opt.is("-h")) return std::fputs(hermes_help::kText, stdout), 0;
    if (opt.is("--out")) o.out = opt.value();
    else if (opt.is("--json")) o.json_out = opt.value();
    else if (opt.is("--bandwidths")) o.bandwidths = system::bench::split(opt.value());
    else if (opt.is("--duration")) o.duration = opt.number(1, 1e5);
    else if (opt.is("--tracking-dir")) o.tracking_dir = opt.value();
    else if (opt.is("--lost-start")) o.lost_start_s = opt.number(0, 80);
    else if (opt.is("--lost-after")) o.lost_after_s = opt.number(1, 36);
    else if (opt.is("--plain")) o.realistic = false;
    else if (opt.is("--set")) o.overrides.push_back(opt.value());
    else return opt.unknown();
  }
  if (o.bandwidths.empty()) return std::fprintf(stderr, "hermes_bench_multisession: --bandwidths is empty\n"), 2;
  if (o.tracking_dir.empty()) o.tracking_dir = (fs::path(o.out) / "tracking").string();
  const std::string data = std::string(HERMES_SOURCE_DIR) + "/data_cache/mh_full" + (o.realistic ? "_realistic" : "");
  const std::vector<std::string> seqs = system::bench::split(system::bench::kMachineHall);
  const std::vector<std::string> settings = {o.realistic ? "render.realistic=true" : render::kPlainLook};
  if (Status s = system::ensureWholeRenders(data, seqs, system::bench::groundTruthDir(), 20, settings); !s)
    return std::fprintf(stderr, "hermes_bench_multisession: %s\n", s.error().c_str()), 1;
  auto robots = robotsOf(o, data, seqs);
  if (!robots.ok()) return std::fprintf(stderr, "hermes_bench_multisession: %s\n", robots.error().c_str()), 1;
  const Robots mission1(robots->begin(), robots->begin() + 3), mission2(robots->begin() + 3, robots->end());
  const json setup = {{"bench", "multisession"}, {"data", data}, {"duration_s", o.duration},
                      {"overrides", o.overrides}};
  auto store = system::BenchStore::open(o.out, setup);
  if (!store.ok()) return std::fprintf(stderr, "hermes_bench_multisession: %s\n", store.error().c_str()), 2;

  json result = setup;
  result["mission1"] = {"MH_01_easy", "MH_02_easy", "MH_03_medium"};
  result["mission2"] = {"MH_04_difficult", "MH_05_difficult"};
  result["runs"] = json::array();
  for (const std::string& bw : o.bandwidths) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "_%g", std::atof(bw.c_str()));
    const std::string suffix = buf;
    auto stored = [&](const std::string& name, const Robots& rs, const std::vector<std::string>& sets,
                      const std::optional<eval::Alignment>& al) -> Expected<json> {
      if (auto row = store->find(name)) return *row;
      std::fprintf(stderr, "hermes_bench_multisession: %s (%zu robots, %s Mbit/s)\n", name.c_str(), rs.size(),
                   std::atof(bw.c_str()) > 0 ? bw.c_str() : "unlimited");
      auto j = runMission(o, name, rs, bw, sets, store->runDir(name), al);
      if (!j.ok()) return Error{name + ": " + j.error()};
      (*j)["run"] = name;
      if (Status s = store->save(name, *j); !s) return Error{s.error()};
      return j;
    };
    auto m1 = stored("mission1" + suffix, mission1, {}, std::nullopt);
    if (!m1.ok()) return std::fprintf(stderr, "hermes_bench_multisession: %s\n", m1.error().c_str()), 1;
    const std::string prior = (fs::path(store->runDir("mission1" + suffix)) / "map").string();
    auto resumed = stored("resumed" + suffix, mission2, {"server.prior_map=" + prior}, alignmentOf(*m1));
    if (!resumed.ok()) return std::fprintf(stderr, "hermes_bench_multisession: %s\n", resumed.error().c_str()), 1;
    auto empty = stored("empty" + suffix, mission2, {}, std::nullopt);
    if (!empty.ok()) return std::fprintf(stderr, "hermes_bench_multisession: %s\n", empty.error().c_str()), 1;
    printRow("mission1" + suffix, *m1);
    printRow("resumed" + suffix, *resumed);
    printRow("empty" + suffix, *empty);
    json entry = json::object();
    entry["bandwidth_mbitps"] = std::atof(bw.c_str());
    entry["mission1"] = *m1;
    entry["resumed"] = *resumed;
    entry["empty"] = *empty;
    entry["downlink_budget_bytes_per_robot"] = resumed->value("downlink_budget_bytes_per_robot", 0.0);
    result["runs"].push_back(entry);
  }
  // A robot lost mid-hall: MH_04 from lost_start_s, its camera dark for 2 s
  // lost_after_s later, flying on mission 1's map (first bandwidth), with the
  // downlink and without. Tracked live: a recording does not start new maps.
  const std::string bw0 = o.bandwidths.front();
  char buf[32];
  std::snprintf(buf, sizeof buf, "_%g", std::atof(bw0.c_str()));
  const std::string prior0 = (fs::path(store->runDir("mission1" + std::string(buf))) / "map").string();
  const fs::path lost_view = fs::path(o.out) / "views" / "MH_04_lost";
  auto w = system::writeEurocWindow((fs::path(data) / "MH_04_difficult").string(), o.lost_start_s, 40, lost_view.string());
  if (!w.ok()) return std::fprintf(stderr, "hermes_bench_multisession: %s\n", w.error().c_str()), 1;
  auto dark_end = system::blackOutFrames(lost_view.string(), o.lost_after_s, o.lost_after_s + 2);
  if (!dark_end.ok()) return std::fprintf(stderr, "hermes_bench_multisession: %s\n", dark_end.error().c_str()), 1;
  Options live = o;
  live.tracking_dir.clear();
  json lost = {{"start_s", o.lost_start_s}, {"dark_from_s", o.lost_after_s}, {"dark_s", 2.0}};
  for (const bool down : {true, false}) {
    const std::string name = std::string(down ? "lost_borrowed" : "lost_no_downlink") + buf;
    json row;
    if (auto r = store->find(name)) {
      row = *r;
    } else {
      std::fprintf(stderr, "hermes_bench_multisession: %s (MH_04 from %g s, dark %g-%g s)\n", name.c_str(),
                   o.lost_start_s, o.lost_after_s, o.lost_after_s + 2);
      auto j = runMission(live, name, {{"MH_04_lost", lost_view}}, bw0,
                          {"server.prior_map=" + prior0, down ? "server.downlink.enabled=true" : "server.downlink.enabled=false"},
                          store->runDir(name), std::nullopt);
      if (!j.ok()) return std::fprintf(stderr, "hermes_bench_multisession: %s: %s\n", name.c_str(), j.error().c_str()), 1;
      (*j)["run"] = name;
      if (Status st = store->save(name, *j); !st) return std::fprintf(stderr, "hermes_bench_multisession: %s\n", st.error().c_str()), 1;
      row = *j;
    }
    const json& a = row["per_agent"].front();
    json out = {{"run", name}, {"sessions", a["sessions"]}, {"borrowed_relocalisations", a["borrowed_relocalisations"]},
                {"global_pose_rmse_m", a["global_pose_rmse_m"]}, {"bytes_down", a["bytes_down"]}};
    out["new_session_placed_after_s"] = nullptr;  // from the new session's start, on the robot's clock
    if (a["sessions"].size() >= 2 && a["sessions"][1]["placed_s"].is_number())
      out["new_session_placed_after_s"] =
          a["sessions"][1]["placed_s"].get<double>() - a["sessions"][1]["started_s"].get<double>();
    std::fprintf(stderr, "%-22s sessions %zu  new session placed after %5.2f s%s  own global pose %5.1f cm RMSE\n",
                 name.c_str(), a["sessions"].size(), num(out, "new_session_placed_after_s"),
                 a["sessions"].size() >= 2 && a["sessions"][1].value("by_borrowed", false) ? " (borrowed map)" : "",
                 num(a, "global_pose_rmse_m") * 100);
    lost[down ? "with_borrowed_map" : "without_downlink"] = out;
  }
  result["lost_robot"] = lost;

  // The first bandwidth's pair at the top: what the checks read.
  const json& first = result["runs"].front();
  result["resumed"] = first["resumed"];
  result["empty"] = first["empty"];
  result["downlink_budget_bytes_per_robot"] = first["downlink_budget_bytes_per_robot"];
  if (o.json_out.empty()) {
    std::cout << result.dump(2) << "\n";
    return 0;
  }
  std::ofstream f(o.json_out);
  f << result.dump(2) << "\n";
  if (!f) return std::fprintf(stderr, "hermes_bench_multisession: cannot write %s\n", o.json_out.c_str()), 1;
  std::fprintf(stderr, "hermes_bench_multisession: %s\n", o.json_out.c_str());
  return 0;
}
