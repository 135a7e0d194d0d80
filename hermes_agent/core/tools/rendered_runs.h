// Helpers of hermes_bench_frontend for rendered sequences: render a slice of a
// shipped trajectory with hermes_sim once (cached under a folder named by every
// render setting), then feed every frame of a dataset folder to a Tracker and
// evaluate it: ATE of the body trajectory (SE(3) alignment, as hermes_run),
// lost rate, keyframes (and how many the entropy rule designated), tracking
// time per frame and the local-mapping statistics of every keyframe.
#pragma once

#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <string>
#include <vector>


#include "hermes/agent/dataset_feed.h"
#include "hermes/agent/tracker.h"
#include "hermes/core/crc32.h"
#include "hermes/core/dataset.h"
#include "hermes/core/evaluation.h"
#include "hermes/core/render/settings.h"
#include "hermes/core/render_cache.h"

namespace hermes::bench {

/// A slice of config/trajectories/<stem>.txt rendered as EuRoC stereo.
struct RenderSpec {
  std::string stem;            ///< e.g. "V1_01_easy"
  double start_s = 0;          ///< seconds after the trajectory's first pose
  double duration_s = 20;      ///< [s]
  double poor_fraction = 0.25; ///< hermes_sim --poor-fraction (0.25 = its default scene)
  int seed = 1;
  /// hermes_sim --set key=value; none: the realistic look, {render::kPlainLook}: the plain one
  std::vector<std::string> settings;

  /// The cache folder's name. The plain look has no suffix (it was the default
  /// when these folders were first made); no settings means realistic and is
  /// named as render.realistic=true always was.
  std::string key() const {
    char buf[256];
    std::snprintf(buf, sizeof buf, "%s_s%g_d%g_pf%g_seed%d", stem.c_str(), start_s, duration_s,
                  poor_fraction, seed);
    std::string k = buf;
    const std::vector<std::string> named =
        settings.empty() ? std::vector<std::string>{"render.realistic=true"} : settings;
    if (named != std::vector<std::string>{render::kPlainLook}) {  // the folder also records them
      std::string all;
      for (const std::string& s : named) all += s + ";";
      std::snprintf(buf, sizeof buf, "_set%08x", crc32(all.data(), all.size()));
      k += buf;
    }
    return k;
  }
  std::string describe() const {
    char buf[256];
    std::snprintf(buf, sizeof buf, "%s %g-%g s, hermes_sim --seed %d --poor-fraction %g",
                  stem.c_str(), start_s, start_s + duration_s, seed, poor_fraction);
    return buf;
  }
};

/// Dataset folder of `spec` under `cache_root`, rendering it first when absent.
inline Expected<std::string> renderCached(const RenderSpec& spec, const std::string& cache_root,
                                          const std::string& trajectories_dir) {
  RenderRequest req;
  req.trajectories = {trajectories_dir + "/" + spec.stem + ".txt"};
  req.start_s = spec.start_s;
  req.duration_s = spec.duration_s;
  req.seed = spec.seed;
  req.poor_fraction = spec.poor_fraction;
  req.settings = spec.settings;
  const std::string folder = cache_root + "/" + spec.key();
  if (Status s = hermes::renderCached(req, folder); !s) return Error{s.error()};
  return folder + "/" + spec.stem;
}

/// Everything one tracked sequence yields.
struct SequenceRun {
  int frames = 0, lost = 0;  ///< lost: not tracked (lost or not yet initialised)
  int keyframes = 0, landmarks = 0;
  int entropy_keyframes = 0;       ///< keyframes at which the entropy rule fired
  int entropy_only_keyframes = 0;  ///< ... and no covisibility rule did
  double ate_rmse_m = -1;     ///< -1 when the trajectory could not be evaluated
  std::size_t ate_matched = 0;
  std::string ate_error;
  std::vector<double> track_ms;            ///< Tracker::feed per frame (wall time)
  std::vector<double> track_cpu_ms;        ///< ... process CPU time (less load-sensitive)
  std::vector<double> keyframe_cpu_ms;     ///< ... of the feeds that inserted a keyframe
  std::vector<LocalMappingStats> mapping;  ///< one per inserted keyframe (after the first)
  std::vector<double> entropy_ratio;       ///< r = H / mean(FIFO) of every frame once the FIFO is full (policy entropy)
  double lostRate() const { return frames > 0 ? double(lost) / frames : 0.0; }
};

/// Feeds every frame (at most max_frames) of the dataset folder to one Tracker.
inline Expected<SequenceRun> trackDataset(const std::string& dir, const TrackerParams& params,
                                          int max_frames = -1) {
  auto ds = Dataset::open(dir);
  if (!ds.ok()) return Error{ds.error()};
  const DatasetInfo& info = (*ds)->info();
  Tracker tracker(params, info.K, info.baseline);
  const SE3 T_C_B = info.T_B_C.inverse();
  Trajectory est;
  SequenceRun out;
  std::size_t n = (*ds)->size();
  if (max_frames >= 0) n = std::min<std::size_t>(n, std::size_t(max_frames));
  for (std::size_t i = 0; i < n; ++i) {
    auto frame = loadCameraFrame(**ds, i);
    if (!frame.ok()) return Error{frame.error()};
    const auto t0 = std::chrono::steady_clock::now();
    const std::clock_t c0 = std::clock();
    auto r = tracker.feed(*frame);
    const double cpu_ms = 1000.0 * double(std::clock() - c0) / CLOCKS_PER_SEC;
    out.track_ms.push_back(
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    out.track_cpu_ms.push_back(cpu_ms);
    if (!r.ok()) return Error{dir + ": " + r.error()};
    if (r->new_keyframe) out.keyframe_cpu_ms.push_back(cpu_ms);
    if (params.keyframe.policy == "entropy" && out.frames >= params.keyframe.entropy_window &&
        std::isfinite(r->keyframe.ratio))
      out.entropy_ratio.push_back(r->keyframe.ratio);
    ++out.frames;
    if (r->new_keyframe) {
      const KeyframeDecision& d = r->keyframe;
      out.entropy_keyframes += d.by_entropy;
      out.entropy_only_keyframes += d.by_entropy && !d.by_tracked_ratio && !d.by_max_frames;
      if (tracker.keyframes().size() > 1) out.mapping.push_back(r->mapping);
    }
    if (r->status != TrackingStatus::kOk) {
      ++out.lost;
      continue;
    }
    est.push_back({frame->stamp, r->T_W_C * T_C_B});  // odometry <- body
  }
  out.keyframes = int(tracker.keyframes().size());
  for (const Landmark& l : tracker.landmarks()) out.landmarks += !tracker.isLandmarkBad(l.id);
  if (info.groundtruth.empty()) {
    out.ate_error = "no ground truth";
  } else if (est.size() < 3) {
    out.ate_error = "fewer than 3 tracked frames";
  } else {
    auto ev = eval::evaluateTrajectory(info.groundtruth, est, eval::EvalParams(), dir);
    if (ev.ok()) {
      out.ate_rmse_m = ev->ate.trans_m.rmse;
      out.ate_matched = ev->ate.trans_m.count;
    } else {
      out.ate_error = ev.error();
    }
  }
  return out;
}

}  // namespace hermes::bench
