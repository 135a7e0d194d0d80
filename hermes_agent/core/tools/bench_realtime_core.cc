// hermes_bench_realtime_core: one agent fed in real time without ROS. A rendered
// sequence (V1_01 ground truth, procedural scene; stereo with the EuRoC
// calibration at 20 Hz, or --format tum: RGB-D at 30 Hz) is
// held in memory and handed to AgentPipeline::feed at the pace of its stamps
// (frame i arrives at t0 + stamp_i - stamp_0; a feed that returns late delays
// the next frames, as a camera callback queue would). Run once in synchronous
// mode and once in parallel mode (agent.parallel), it prints JSON per mode:
//   frames, tracked fraction, tracking latency (arrival -> pose) median / p95 /
//   max, the track stage (Tracker::feed in feed()) median / p95 and their ratio,
//   feed() as a whole, process CPU time per wall second (cores), ATE, and the
//   stage counters (BA jobs merged / skipped, windows queued / merged).
// The agent has no uplink: windows are distilled (distill.* as configured,
// default milp) and encoded, then only counted.
// Usage: tools/help/hermes_bench_realtime_core.txt (`hermes_bench_realtime_core --help`).
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "hermes/agent/agent_pipeline.h"
#include "hermes/agent/dataset_feed.h"
#include "hermes/agent/run_config.h"
#include "hermes/core/dataset.h"
#include "hermes/core/evaluation.h"
#include "hermes/core/render/dataset_writer.h"
#include "hermes/core/render/rig.h"
#include "hermes/core/render/scene.h"
#include "hermes_help/hermes_bench_realtime_core.h"  // tools/help/hermes_bench_realtime_core.txt

using namespace hermes;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {

struct Clip {
  std::vector<CameraFrame> frames;
  agent::AgentCamera camera;
  Trajectory groundtruth;
};

/// Renders the slice into `dir` once (kept as a cache), then loads it.
Expected<Clip> loadClip(const std::string& dir, bool tum, double rate_hz, double start_s,
                        double seconds) {
  if (!fs::exists(dir + "/done")) {
    const std::string gt_path = std::string(HERMES_TRAJECTORY_DIR) + "/V1_01_easy.txt";
    auto gt = readTumTrajectory(gt_path);
    if (!gt.ok()) return Error{gt.error()};
    const PinholeRadtan cam0 = render::eurocCam0(), cam1 = render::eurocCam1();
    std::vector<Vec3> positions;
    render::appendRigPositions(*gt, {cam0.T_B_C, cam1.T_B_C}, &positions);
    render::SceneParams sp;
    sp.seed = 7;
    auto scene = render::buildScene(positions, sp);
    if (!scene.ok()) return Error{scene.error()};
    render::SequenceSpec spec;
    spec.start_s = start_s;
    spec.duration_s = seconds;
    spec.rate_hz = rate_hz;
    spec.seed = 7;
    fs::remove_all(dir);
    RgbdCamera rgbd = render::defaultRgbd();
    rgbd.rate_hz = rate_hz;
    auto written = tum ? render::writeTumSequence(dir, *scene, *gt, rgbd, spec)
                       : render::writeEurocSequence(dir, *scene, *gt, cam0, cam1, spec);
    if (!written.ok()) return Error{written.error()};
    std::ofstream(dir + "/done") << "rendered\n";
  }
  auto ds = Dataset::open(dir);
  if (!ds.ok()) return Error{ds.error()};
  const DatasetInfo& info = (*ds)->info();
  Clip clip;
  clip.camera = agent::AgentCamera{info.K, info.baseline, info.T_B_C};
  clip.groundtruth = info.groundtruth;
  for (std::size_t i = 0; i < (*ds)->size(); ++i) {
    auto f = loadCameraFrame(**ds, i);
    if (!f.ok()) return Error{f.error()};
    clip.frames.push_back(std::move(*f));
  }
  return clip;
}

double cpuSeconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
         1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

nlohmann::json summary(std::vector<double> v) {
  nlohmann::json j;
  j["n"] = v.size();
  if (v.empty()) return j;
  j["median"] = timing::percentile(v, 50);
  j["p95"] = timing::percentile(v, 95);
  j["max"] = *std::max_element(v.begin(), v.end());
  return j;
}

Expected<nlohmann::json> runMode(const Clip& clip, agent::AgentPipelineParams params,
                                 bool parallel) {
  params.threads.parallel = parallel;
  auto created = agent::AgentPipeline::create(params, "V1_01", clip.camera);
  if (!created.ok()) return Error{created.error()};
  agent::AgentPipeline& p = **created;
  std::vector<double> latency_ms;
  const double stamp0 = clip.frames.front().stamp;
  const double cpu0 = cpuSeconds();
  const auto t0 = Clock::now();
  for (const CameraFrame& f : clip.frames) {
    const auto arrival =
        t0 + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(f.stamp - stamp0));
    std::this_thread::sleep_until(arrival);
    auto r = p.feed(f);
    if (!r.ok()) return Error{r.error()};
    latency_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - arrival).count());
  }
  const double feed_wall_s = std::chrono::duration<double>(Clock::now() - t0).count();
  p.flushWindow();  // end of sequence: workers drained
  const double wall_s = std::chrono::duration<double>(Clock::now() - t0).count();
  const double cpu_s = cpuSeconds() - cpu0;

  nlohmann::json j;
  j["mode"] = parallel ? "parallel" : "synchronous";
  j["frames"] = p.frames();
  j["tracked_fraction"] = p.frames() ? double(p.frames() - p.lostFrames()) / double(p.frames()) : 0.0;
  j["latency_ms"] = summary(latency_ms);
  const auto timings = p.timings().summary();
  auto stage = [&](const std::string& name) {
    nlohmann::json s;
    auto it = timings.find(name);
    if (it == timings.end()) return s;
    s["median"] = it->second.median;
    s["p95"] = it->second.p95;
    s["count"] = it->second.count;
    if (it->second.median > 0) s["p95_over_median"] = it->second.p95 / it->second.median;
    return s;
  };
  for (const char* name : {"track", "window", "agent_total", "distill", "encode"})
    j["stages_ms"][name] = stage(name);
  j["wall_s"] = wall_s;
  j["sequence_s"] = clip.frames.back().stamp - stamp0;
  j["feed_wall_s"] = feed_wall_s;
  j["cpu_s"] = cpu_s;
  j["cpu_cores"] = cpu_s / wall_s;
  const agent::AgentThreadStats st = p.threadStats();
  j["mapping"] = {{"keyframes", st.mapping.keyframes}, {"ba_jobs", st.mapping.ba_jobs},
                  {"merged", st.mapping.merged},       {"skipped", st.mapping.skipped},
                  {"max_waiting", st.mapping.max_waiting},
                  {"ba_ms_mean", st.mapping.ba_jobs ? st.mapping.ba_ms_total / st.mapping.ba_jobs : 0.0},
                  {"ba_ms_max", st.mapping.ba_ms_max},
                  {"structure_ms_mean", st.mapping.keyframes ? st.mapping.structure_ms_total /
                                                                   double(st.mapping.keyframes)
                                                             : 0.0},
                  {"structure_ms_max", st.mapping.structure_ms_max}};
  const agent::WindowCounters w = p.windows();
  j["windows"] = {{"cut", w.windows},          {"sent", w.sent},
                  {"queued", st.windows.pushed}, {"merged_in_queue", st.windows.merged},
                  {"queue_high_water", st.windows.high_water}};
  eval::EvalParams ep;
  ep.align = eval::AlignMode::kSE3;
  auto ev = eval::evaluateTrajectory(clip.groundtruth, p.trajectory(), ep, "V1_01");
  if (ev.ok()) j["ate_se3_m"] = ev->ate.trans_m.rmse;
  return j;
}

}  // namespace

int main(int argc, char** argv) {
  double start_s = 10, seconds = 20, rate_hz = 0;
  std::string format = "euroc", mode = "both", json_out, cache = "/tmp/hermes_bench_realtime_core";
  std::vector<std::string> sets;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::cerr << a << " needs a value\n";
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--help" || a == "-h") {
      std::cout << hermes_help::kText;
      return 0;
    } else if (a == "--format") format = next();
    else if (a == "--rate") rate_hz = std::stod(next());
    else if (a == "--start") start_s = std::stod(next());
    else if (a == "--seconds") seconds = std::stod(next());
    else if (a == "--mode") mode = next();
    else if (a == "--cache") cache = next();
    else if (a == "--json") json_out = next();
    else if (a == "--set") sets.push_back(next());
    else {
      std::cerr << hermes_help::kText;
      return 2;
    }
  }
  if (format != "euroc" && format != "tum") {
    std::cerr << "--format must be euroc or tum\n";
    return 2;
  }
  if (rate_hz <= 0) rate_hz = format == "tum" ? 30 : 20;
  if (mode != "both" && mode != "sync" && mode != "parallel") {
    std::cerr << "--mode must be both, sync or parallel\n";
    return 2;
  }
  auto config = loadConfig("", sets);
  if (!config.ok()) {
    std::cerr << config.error() << "\n";
    return 2;
  }
  agent::AgentPipelineParams params;
  params.uplink.buffer.dir = cache + "/spool";  // unused: no uplink attached
  if (Status s = params.read(*config); !s) {
    std::cerr << s.error() << "\n";
    return 2;
  }
  if (Status s = agent::rejectUnreadKeys(*config); !s) {
    std::cerr << s.error() << "\n";
    return 2;
  }
  char key[128];
  std::snprintf(key, sizeof key, "/V1_01_%s_r%g_s%g_d%g", format.c_str(), rate_hz, start_s,
                seconds);
  auto clip = loadClip(cache + key, format == "tum", rate_hz, start_s, seconds);
  if (!clip.ok()) {
    std::cerr << clip.error() << "\n";
    return 1;
  }
  nlohmann::json out;
  char what[256];
  std::snprintf(what, sizeof what, "V1_01 rendered from %g s, %g s at %g Hz, %s", start_s, seconds,
                rate_hz, format == "tum" ? "RGB-D (TUM layout)" : "stereo 752x480 (EuRoC layout)");
  out["sequence"] = what;
  out["hardware_threads"] = std::thread::hardware_concurrency();
  for (bool parallel : {false, true}) {
    if ((mode == "sync" && parallel) || (mode == "parallel" && !parallel)) continue;
    auto r = runMode(*clip, params, parallel);
    if (!r.ok()) {
      std::cerr << r.error() << "\n";
      return 1;
    }
    out[parallel ? "parallel" : "synchronous"] = *r;
  }
  const std::string text = out.dump(2);
  std::cout << text << "\n";
  if (!json_out.empty()) std::ofstream(json_out) << text << "\n";
  return 0;
}
