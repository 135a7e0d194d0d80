// hermes_bench_distill: distillation timing and quality per strategy on windows
// built from real EuRoC ground truth (MH_01_easy, V1_01_easy) by the synthetic
// window generator. Prints JSON (stdout, and --json FILE).
//
// Usage: tools/help/hermes_bench_distill.txt (`hermes_bench_distill --help`).
//
// Per strategy: selection time (Eq. 14 instance with K = 60 and a landmark byte
// budget of 40 % of the unconstrained selection), full Distiller time with the
// coordinator on (bandwidth cycling 15/30/60 kB/s), solver status counts, bytes
// vs budget, the MILP objective relative to its greedy warm start, and the
// MILP's remaining optimality gap against CBC's lower bound.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "hermes/core/value_stats.h"
#include "hermes/distill/distiller.h"
#include "hermes/distill/selectors.h"
#include "hermes/distill/synthetic_window.h"
#include "hermes_help/hermes_bench_distill.h"  // tools/help/hermes_bench_distill.txt

using namespace hermes;
using namespace hermes::distill;
using json = nlohmann::json;

namespace {


}  // namespace

int main(int argc, char** argv) {
  // Trajectories: --data DIR (EuRoC ground truths, TUM format), else the shipped ones.
  std::string json_out, data_dir = HERMES_TRAJECTORY_DIR;
  int windows = 10;
  std::vector<std::string> overrides;
  std::uint64_t seed = 7;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "hermes_bench_distill: %s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--json") json_out = next();
    else if (a == "--windows") windows = std::max(1, std::atoi(next().c_str()));
    else if (a == "--data") data_dir = next();
    else if (a == "--seed") seed = std::strtoull(next().c_str(), nullptr, 10);
    else if (a == "--set") overrides.push_back(next());
    else if (a == "--help" || a == "-h") {
      std::fputs(hermes_help::kText, stdout);
      return 0;
    } else {
      std::fprintf(stderr, "hermes_bench_distill: unknown argument '%s'\n", a.c_str());
      return 2;
    }
  }
  DistillParams base;
  {
    auto cfg = Config::fromString("{}", "--set");
    if (!cfg) {
      std::fprintf(stderr, "hermes_bench_distill: %s\n", cfg.error().c_str());
      return 2;
    }
    for (const auto& o : overrides) {
      const Status st = cfg->applyOverride(o);
      if (!st) {
        std::fprintf(stderr, "hermes_bench_distill: --set %s: %s\n", o.c_str(), st.error().c_str());
        return 2;
      }
    }
    const Status st = base.read(*cfg);
    if (!st) {
      std::fprintf(stderr, "hermes_bench_distill: %s\n", st.error().c_str());
      return 2;
    }
    for (const auto& k : cfg->unusedKeys()) {
      std::fprintf(stderr, "hermes_bench_distill: unknown key '%s'\n", k.c_str());
      return 2;
    }
  }
  const std::vector<std::string> strategies = {"milp", "greedy_logdet", "stability", "anms", "none"};
  const std::vector<std::string> sequences = {"MH_01_easy", "V1_01_easy"};
  std::map<std::string, std::vector<double>> select_ms, distill_ms, objective_ratio, bytes_ratio;
  std::map<std::string, std::map<std::string, int>> statuses, distill_statuses;
  std::map<std::string, int> over_budget, deferred;
  std::vector<double> milp_gap_vs_greedy, milp_bound_gap, window_lms, window_obs;
  int n_windows = 0;
  for (const std::string& seq_name : sequences) {
    SyntheticWindowParams wp;
    wp.seed = seed;
    auto scene = makeSceneFromTum(data_dir + "/" + seq_name + ".txt", wp);
    if (!scene) {
      std::fprintf(stderr, "hermes_bench_distill: %s\n", scene.error().c_str());
      return 1;
    }
    const double span = scene->duration() - wp.duration_s - 1.0;
    for (int w = 0; w < windows; ++w) {
      const double t = 5.0 + (span - 5.0) * w / std::max(1, windows - 1);
      auto win = scene->window(t, static_cast<std::uint64_t>(w));
      if (!win) continue;
      ++n_windows;
      std::fprintf(stderr, "\r%s window %d/%d", seq_name.c_str(), w + 1, windows);
      window_lms.push_back(static_cast<double>(win->submap.landmarks.size()));
      window_obs.push_back(static_cast<double>(win->submap.observationCount()));
      DistillParams params = base;
      // Selection only: trimmed to max_keyframes, K = 60, 40 % landmark budget.
      const TrimResult trim = trimKeyframes(win->submap, params.max_keyframes, params);
      const Submap trimmed = applyKeyframeTrim(win->submap, trim.kept);
      const LandmarkScores scores = computeScores(trimmed, win->hint, 0, params);
      SelectionProblem prob = buildSelectionProblem(trimmed, scores, 60, INFINITY,
                                                    params.bytes_lm, params.bytes_obs, params);
      double all_bytes = 0;
      for (double b : prob.bytes) all_bytes += b;
      prob.budget = 0.4 * all_bytes;
      for (const std::string& s : strategies) {
        auto sel = makeLandmarkSelector(s, params);
        const auto t0 = std::chrono::steady_clock::now();
        const SelectionResult r = (*sel)->select(prob);
        select_ms[s].push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
        statuses[s][toString(r.status)]++;
        if (s != "none") objective_ratio[s].push_back(r.objective);
        if (s == "milp") {
          milp_gap_vs_greedy.push_back((r.greedy_objective - r.objective) / std::abs(r.greedy_objective));
          milp_bound_gap.push_back(std::max(0.0, r.objective - r.lower_bound) / std::abs(r.objective));
        }
      }
      // Full pipeline with the coordinator.
      const double rates[3] = {15000, 30000, 60000};
      CoordinatorInput in;
      in.bandwidth_Bps = rates[w % 3];
      for (const std::string& s : strategies) {
        DistillParams dp = base;
        dp.strategy = s;
        Distiller d(dp, referenceEncodedSize);
        const DistillResult res = d.distill(win->submap, win->hint, in);
        distill_ms[s].push_back(res.report.time_total_ms);
        distill_statuses[s][res.report.deferred ? std::string("deferred") : res.report.selection_status]++;
        if (res.report.deferred) deferred[s]++;
        else if (res.report.over_budget) over_budget[s]++;
        if (!res.report.deferred)
          bytes_ratio[s].push_back(res.report.bytes_actual / res.report.budget_bytes);
      }
    }
  }
  std::fprintf(stderr, "\n");
  json out;
  out["bench"] = "distill";
  out["windows"] = n_windows;
  out["sequences"] = sequences;
  out["window_landmarks"] = distributionJson(window_lms);
  out["window_observations"] = distributionJson(window_obs);
  out["target"] = "milp selection <= 50 ms median per 5-s window, one core";
  for (const std::string& s : strategies) {
    json j;
    j["select_ms"] = distributionJson(select_ms[s]);
    j["distill_ms"] = distributionJson(distill_ms[s]);
    j["status_counts"] = statuses[s];
    j["distill_status_counts"] = distill_statuses[s];
    j["bytes_over_budget_ratio"] = distributionJson(bytes_ratio[s]);
    j["windows_over_budget"] = over_budget[s];
    j["windows_deferred"] = deferred[s];
    if (s != "none") j["eq14_objective"] = distributionJson(objective_ratio[s]);
    out["strategies"][s] = j;
  }
  out["milp_improvement_over_greedy"] = distributionJson(milp_gap_vs_greedy);  // (greedy − milp) / greedy
  out["milp_optimality_gap"] = distributionJson(milp_bound_gap);  // (milp − CBC bound) / milp
  const std::string text = out.dump(2);
  std::printf("%s\n", text.c_str());
  if (!json_out.empty()) {
    std::ofstream f(json_out);
    if (!f) {
      std::fprintf(stderr, "hermes_bench_distill: cannot write %s\n", json_out.c_str());
      return 1;
    }
    f << text << "\n";
  }
  return 0;
}
