// hermes_bench_distill_replay: the distiller on an agent's real windows, replayed
// from tracking recordings (hermes_run --record-tracking DIR writes
// DIR/<agent>.htrk). One Distiller per recording and link rate takes the
// recorded windows in order with their motion hints, as the agent's window step
// does: a deferred window is carried into the next. Prints JSON (stdout, and
// --json FILE) with the wall and CPU time per window (total and per stage) and a digest of
// every distilled submap, so two builds can be checked to select the same.
//
// Usage: tools/help/hermes_bench_distill_replay.txt (`--help`).
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "hermes/agent/submap_window.h"
#include "hermes/agent/tracking_log.h"
#include "hermes/agent/window_step.h"
#include "hermes/core/value_stats.h"
#include "hermes/core/wire_format.h"
#include "hermes/distill/distiller.h"
#include "hermes_help/hermes_bench_distill_replay.h"  // tools/help/hermes_bench_distill_replay.txt

using namespace hermes;
using json = nlohmann::json;

namespace {


// FNV-1a 64 over what a distilled submap sends (ids, kept observations and keypoints).
struct Digest {
  std::uint64_t h = 1469598103934665603ull;
  void add(std::uint64_t x) {
    for (int b = 0; b < 8; ++b) {
      h ^= (x >> (8 * b)) & 0xffu;
      h *= 1099511628211ull;
    }
  }
};

// CPU time of this thread [ms]: on a shared machine what the distiller itself took.
double threadCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return 1e3 * static_cast<double>(ts.tv_sec) + 1e-6 * static_cast<double>(ts.tv_nsec);
}

std::string hex(std::uint64_t x) {
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(x));
  return buf;
}

std::uint64_t submapDigest(const distill::DistillResult& r) {
  Digest d;
  d.add(r.report.deferred ? 1 : 0);
  d.add(static_cast<std::uint64_t>(r.report.k));
  d.add(static_cast<std::uint64_t>(r.report.loop_keypoints));
  for (const Keyframe& kf : r.submap.keyframes) {
    d.add(kf.id);
    d.add(kf.keypoints.size());
    for (LandmarkId id : kf.keypoint_landmark) d.add(id);
  }
  for (const Landmark& lm : r.submap.landmarks) {
    d.add(lm.id);
    for (const Observation& ob : lm.observations) {
      d.add(ob.keyframe);
      d.add(ob.keypoint);
    }
  }
  if (r.held_back) d.add(r.held_back->keyframes.size());
  return d.h;
}

}  // namespace

int main(int argc, char** argv) {
  std::string json_out;
  std::vector<std::string> recordings, overrides;
  std::vector<double> rates_kBps;
  int unplaced_windows = 1;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "hermes_bench_distill_replay: %s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--json") json_out = next();
    else if (a == "--recording") recordings.push_back(next());
    else if (a == "--rate") rates_kBps.push_back(std::atof(next().c_str()));
    else if (a == "--unplaced-windows") unplaced_windows = std::max(0, std::atoi(next().c_str()));
    else if (a == "--set") overrides.push_back(next());
    else if (a == "--help" || a == "-h") {
      std::fputs(hermes_help::kText, stdout);
      return 0;
    } else {
      std::fprintf(stderr, "hermes_bench_distill_replay: unknown argument '%s'\n", a.c_str());
      return 2;
    }
  }
  if (recordings.empty()) {
    std::fprintf(stderr, "hermes_bench_distill_replay: give at least one --recording FILE.htrk\n");
    return 2;
  }
  if (rates_kBps.empty()) rates_kBps = {0, 400, 50, 12.5};
  distill::DistillParams base;
  base.solver_limits = "work";  // what the offline runner resolves auto to
  {
    auto cfg = Config::fromString("{}", "--set");
    Status st = cfg.ok() ? Status::Ok() : Status(Error{cfg.error()});
    for (const auto& o : overrides)
      if (st) st = cfg->applyOverride(o);
    if (st) st = base.read(*cfg);
    if (st)
      for (const auto& k : cfg->unusedKeys()) st = Error{"unknown key '" + k + "'"};
    if (!st) {
      std::fprintf(stderr, "hermes_bench_distill_replay: %s\n", st.error().c_str());
      return 2;
    }
  }
  json out;
  out["bench"] = "distill_replay";
  out["strategy"] = base.strategy;
  out["solver_limits"] = base.solver_limits;
  std::vector<double> all_total, all_cpu;
  Digest all_digest;
  for (const std::string& path : recordings) {
    auto log = agent::readTrackingLog(path);
    if (!log) {
      std::fprintf(stderr, "hermes_bench_distill_replay: %s\n", log.error().c_str());
      return 1;
    }
    for (double rate : rates_kBps) {
      distill::Distiller distiller(base, [](const Submap& s) { return encodedSizeUncompressed(s); });
      std::optional<Submap> carry;
      int periods = 0, index = 0;
      std::vector<double> total, cpu, trim, scores, select, encode;
      std::map<std::string, int> statuses;
      json digests = json::array(), windows = json::array();
      for (const agent::TrackingStep& step : log->steps) {
        if (!step.window) continue;
        Submap window = *step.window;
        ++periods;
        if (carry) {
          auto merged = mergeWindows(std::move(*carry), window);
          carry.reset();
          if (merged.ok()) window = std::move(*merged);
          else periods = 1;
          keepNewestKeyframes(&window, agent::kMaxCarryKeyframes);
        }
        distill::CoordinatorInput in;
        const bool unlimited = !(rate > 0);
        in.bandwidth_Bps = unlimited ? 1e9 : rate * 1e3;
        in.link_keeps_up = periods == 1;
        in.placed = index >= unplaced_windows;
        in.period_s = periods * base.window_s;
        const double cpu0 = threadCpuMs();
        const auto t0 = std::chrono::steady_clock::now();
        const distill::DistillResult r = distiller.distill(window, step.motion, in);
        const double ms =
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
        const double cpu_ms = threadCpuMs() - cpu0;
        ++index;
        if (!r.report.ok) {
          std::fprintf(stderr, "hermes_bench_distill_replay: %s\n", r.report.error.c_str());
          return 1;
        }
        // Eq. 15 objective of the keyframes kept (for comparing work limits).
        double trim_objective = 0;
        if (!r.report.deferred) {
          std::vector<int> kept;
          for (std::size_t j = 0, k = 0; j < window.keyframes.size() && k < r.submap.keyframes.size(); ++j)
            if (window.keyframes[j].id == r.submap.keyframes[k].id) {
              kept.push_back(static_cast<int>(j));
              ++k;
            }
          trim_objective = distill::trimObjective(window, kept, base);
        }
        total.push_back(ms);
        cpu.push_back(cpu_ms);
        trim.push_back(r.report.time_trim_ms);
        scores.push_back(r.report.time_scores_ms);
        select.push_back(r.report.time_select_ms);
        encode.push_back(r.report.time_encode_ms);
        statuses[r.report.deferred ? std::string("deferred") : r.report.selection_status]++;
        const std::uint64_t dg = submapDigest(r);
        all_digest.add(dg);
        digests.push_back(hex(dg));
        windows.push_back({{"ms", ms},
                           {"cpu_ms", cpu_ms},
                           {"trim_ms", r.report.time_trim_ms},
                           {"select_ms", r.report.time_select_ms},
                           {"kf_in", r.report.n_kf_in},
                           {"lm_in", r.report.n_lm_in},
                           {"kf", r.report.n_kf},
                           {"lm", r.report.n_lm},
                           {"k", r.report.k},
                           {"rounds", r.report.rounds},
                           {"objective", r.report.objective},
                           {"greedy_objective", r.report.greedy_objective},
                           {"trim_objective", trim_objective},
                           {"trim_status", r.report.trim_status},
                           {"status", r.report.deferred ? std::string("deferred") : r.report.selection_status}});
        if (r.report.deferred) carry = std::move(window);
        else periods = 0;
      }
      all_total.insert(all_total.end(), total.begin(), total.end());
      all_cpu.insert(all_cpu.end(), cpu.begin(), cpu.end());
      json j;
      j["recording"] = path;
      j["rate_kBps"] = rate;
      j["windows"] = total.size();
      j["distill_ms"] = distributionJson(total);
      j["distill_cpu_ms"] = distributionJson(cpu);
      j["trim_ms"] = distributionJson(trim);
      j["scores_ms"] = distributionJson(scores);
      j["select_ms"] = distributionJson(select);
      j["encode_ms"] = distributionJson(encode);
      j["status_counts"] = statuses;
      j["digests"] = digests;
      j["per_window"] = windows;
      out["runs"].push_back(j);
      std::fprintf(stderr, "%s at %g kB/s: %zu windows, median %.1f ms\n", path.c_str(), rate,
                   total.size(), j["distill_ms"].value("median", 0.0));
    }
  }
  out["distill_ms"] = distributionJson(all_total);
  out["distill_cpu_ms"] = distributionJson(all_cpu);
  out["digest"] = hex(all_digest.h);
  out["target"] = "distill <= 50 ms median, <= 150 ms p95 per 5-s window, one core";
  const std::string text = out.dump(2);
  std::printf("%s\n", text.c_str());
  if (!json_out.empty()) {
    std::ofstream f(json_out);
    if (!f) {
      std::fprintf(stderr, "hermes_bench_distill_replay: cannot write %s\n", json_out.c_str());
      return 1;
    }
    f << text << "\n";
  }
  return 0;
}
