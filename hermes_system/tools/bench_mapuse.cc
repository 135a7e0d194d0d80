// hermes_bench_mapuse (`./hermes bench mapuse`): distillation on the agent's
// REAL 5-s windows and how useful the distilled maps are (paper Fig. 15).
//   1. Renders MH_01 and MH_02 in one hall and V1_01 in a hall of its own
//      (cached), runs the stereo front end (Tracker) on MH_01 (first --map-until
//      seconds) and on V1_01 (all of it) and collects their windows.
//   2. Timing on the windows of both sequences: every strategy distils every
//      window with the coordinator on at a fixed planning rate: per-window time
//      median/p95, solver status counts, bytes vs budget, Eq. 14 objective.
//      Selection alone: every window trimmed to distill.max_keyframes, one Eq. 14
//      instance (K = 60, landmark budget 40 % of all landmarks' bytes) solved by
//      every strategy: time median/p95, status counts, objective of each strategy
//      per window relative to greedy_logdet's (median/min), milp vs its greedy
//      warm start and vs CBC's lower bound.
//   3. Map usefulness: for K in {300,200,100,50,30} (coordinator off, fixed K
//      landmarks per keyframe) every strategy distils the windows of the first
//      part of MH_01; the union of the distilled landmarks is the map. Frames
//      from the LATER part of MH_01 and from MH_02 (another robot in the same
//      hall) are localised against it: ORB + brute-force Hamming matching with a
//      ratio test + PnP RANSAC. A frame counts as localised when PnP keeps >= 15
//      inliers and the pose is within 0.10 m and 2 deg of ground truth ("strict":
//      >= 40 inliers, 0.03 m, 1 deg). Recall, median inliers, median error and the
//      encoded bytes of the distilled map per (strategy, K).
// Prints JSON on stdout (or --json FILE) and a table on stderr.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <memory>
#include <map>
#include <string>
#include <tuple>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>

#include "bench_args.h"
#include "hermes/agent/dataset_feed.h"
#include "hermes/agent/orb_extractor.h"
#include "hermes/agent/tracker.h"
#include "hermes/agent/window_cut.h"
#include "hermes/core/evaluation.h"
#include "hermes/core/metrics.h"
#include "hermes/core/render/settings.h"
#include "hermes/core/render_cache.h"
#include "hermes/core/wire_format.h"
#include "hermes/distill/distiller.h"
#include "hermes/distill/keyframe_trimming.h"
#include "hermes/distill/selectors.h"
#include "hermes_help/hermes_bench_mapuse.h"  // tools/help/hermes_bench_mapuse.txt

using namespace hermes;
namespace fs = std::filesystem;

namespace {

const char* const kUsage = hermes_help::kText;

const std::vector<std::string> kStrategies = {"milp", "greedy_logdet", "stability", "anms", "none"};
const std::vector<int> kBudgets = {300, 200, 100, 50, 30};

struct Window {
  Submap submap;
  distill::MotionHint hint;
};

struct Query {
  double t = 0;
  SE3 T_A_C;  ///< ground truth in the map's frame (MH_01's first camera)
  std::vector<Keypoint> keypoints;
  std::vector<Descriptor> descriptors;
};

struct MapPoint {
  Vec3 p_A;
  Descriptor d;
};

double percentile(std::vector<double> v, double q) { return timing::percentile(std::move(v), q); }

nlohmann::json summary(const std::vector<double>& v) {
  if (v.empty()) return nullptr;
  return {{"median", percentile(v, 50)}, {"p95", percentile(v, 95)},
          {"min", *std::min_element(v.begin(), v.end())},
          {"max", *std::max_element(v.begin(), v.end())}, {"n", v.size()}};
}

/// Renders the trajectories (config/trajectories/<name>.txt) into one hall under
/// `data` unless a finished rendering is cached there.
bool renderHall(const fs::path& data, const std::vector<std::string>& names, double duration) {
  RenderRequest req;
  for (const std::string& n : names)
    req.trajectories.push_back(std::string(HERMES_SOURCE_DIR) + "/config/trajectories/" + n + ".txt");
  req.duration_s = duration;
  req.settings = {render::kPlainLook};  // the look of its published figures
  if (Status s = renderCached(req, data.string()); !s) {
    std::fprintf(stderr, "[mapuse] %s\n", s.error().c_str());
    return false;
  }
  return true;
}

struct Fix {
  bool ok = false;      ///< >= 15 inliers, < 0.10 m, < 2 deg
  bool strict = false;  ///< >= 40 inliers, < 0.03 m, < 1 deg
  double err_m = 0, err_deg = 0;
  int inliers = 0;
};

/// Localises one query against the map by matching + PnP RANSAC.
Fix localise(const std::vector<MapPoint>& map, const Query& q,
                                          const PinholeIntrinsics& K) {
  std::vector<cv::Point3f> obj;
  std::vector<cv::Point2f> img;
  for (std::size_t i = 0; i < q.descriptors.size(); ++i) {
    int best = 257, second = 257, arg = -1;
    for (std::size_t j = 0; j < map.size(); ++j) {
      const int d = hammingDistance(q.descriptors[i], map[j].d);
      if (d < best) {
        second = best;
        best = d;
        arg = int(j);
      } else if (d < second) {
        second = d;
      }
    }
    if (arg < 0 || best > 50 || best > 0.8 * second) continue;
    const Vec3& p = map[std::size_t(arg)].p_A;
    obj.emplace_back(float(p.x()), float(p.y()), float(p.z()));
    img.emplace_back(q.keypoints[i].u, q.keypoints[i].v);
  }
  Fix fix;
  if (obj.size() < 15) return fix;
  const cv::Matx33d Km(K.fx, 0, K.cx, 0, K.fy, K.cy, 0, 0, 1);
  cv::Mat rvec, tvec;
  std::vector<int> inliers;
  if (!cv::solvePnPRansac(obj, img, Km, cv::noArray(), rvec, tvec, false, 200, 3.0f, 0.999,
                          inliers) ||
      inliers.size() < 15)
    return fix;
  cv::Mat R;
  cv::Rodrigues(rvec, R);
  Mat3 Re;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) Re(r, c) = R.at<double>(r, c);
  const SE3 T_C_A(Re, Vec3(tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2)));
  const SE3 err = q.T_A_C.inverse() * T_C_A.inverse();
  fix.err_m = err.translation().norm();
  fix.err_deg = eval::relativeAngle(Quat::Identity(), err.quat()) * 180.0 / M_PI;
  fix.inliers = int(inliers.size());
  fix.ok = fix.err_m < 0.10 && fix.err_deg < 2.0;
  fix.strict = fix.ok && fix.inliers >= 40 && fix.err_m < 0.03 && fix.err_deg < 1.0;
  return fix;
}

}  // namespace

int main(int argc, char** argv) {
  double duration = 40, map_until = 25;
  bool timing_only = false;
  std::string cache = std::string(HERMES_SOURCE_DIR) + "/data_cache/bench_mapuse", json_out;
  hermes::system::bench::Options opt(argc, argv, "hermes_bench_mapuse");
  while (opt.next()) {
    if (opt.is("--help") || opt.is("-h")) return std::cout << kUsage, 0;
    if (opt.is("--duration")) duration = opt.number();
    else if (opt.is("--map-until")) map_until = opt.number();
    else if (opt.is("--cache")) cache = opt.value();
    else if (opt.is("--json")) json_out = opt.value();
    else if (opt.is("--timing-only")) timing_only = true;
    else return opt.unknown();
  }
  if (!(duration > map_until + 5) || !(map_until > 5))
    return std::fprintf(stderr, "hermes_bench_mapuse: need 5 < --map-until < --duration - 5\n"), 2;

  char key[64];
  std::snprintf(key, sizeof key, "d%g", duration);
  const fs::path data = fs::path(cache) / key;
  const fs::path data_v1 = fs::path(cache) / (std::string(key) + "_V1_01");  // another room: its own hall
  if (!renderHall(data, {"MH_01_easy", "MH_02_easy"}, duration) ||
      !renderHall(data_v1, {"V1_01_easy"}, duration))
    return 1;

  // 1. Front end on MH_01: windows, and the map frame A (first camera pose).
  auto ds1 = Dataset::open((data / "MH_01_easy").string(), DatasetParams{});
  auto ds2 = Dataset::open((data / "MH_02_easy").string(), DatasetParams{});
  if (!ds1.ok() || !ds2.ok()) return std::fprintf(stderr, "cannot open the rendered data\n"), 1;
  const DatasetInfo& i1 = (*ds1)->info();
  TrackerParams tp;
  Tracker tracker(tp, i1.K, i1.baseline);
  WindowCut cut(tracker, tp.window);
  std::vector<Window> windows;
  std::optional<SE3> T_W_A;  // ground-truth world <- map frame A
  OrbExtractor orb(tp.orb);
  std::vector<Query> queries_same, queries_other;
  const double t0 = (*ds1)->frameTime(0);
  auto gtCamera = [](const DatasetInfo& info, double t, SE3* T) {
    SE3 T_W_B;
    if (!interpolatePose(info.groundtruth, t, &T_W_B)) return false;
    *T = T_W_B * info.T_B_C;
    return true;
  };
  for (std::size_t i = 0; i < i1.frame_count; ++i) {
    auto f = loadCameraFrame(**ds1, i);
    if (!f.ok()) return std::fprintf(stderr, "%s\n", f.error().c_str()), 1;
    const double rel = f->stamp - t0;
    if (rel < map_until) {
      auto r = tracker.feed(*f);
      if (!r.ok()) return std::fprintf(stderr, "%s\n", r.error().c_str()), 1;
      if (!T_W_A && r->status == TrackingStatus::kOk) {
        SE3 T_W_C;
        if (gtCamera(i1, f->stamp, &T_W_C)) T_W_A = T_W_C * r->T_W_C.inverse();
      }
      if (auto w = cut.takeWindowIfDue(f->stamp)) windows.push_back({std::move(*w), cut.motionHint()});
    } else if (i % 5 == 0) {
      auto fs = orb.extract(f->left);
      SE3 T_W_C;
      if (fs.ok() && T_W_A && gtCamera(i1, f->stamp, &T_W_C))
        queries_same.push_back({rel, T_W_A->inverse() * T_W_C, fs->keypoints, fs->descriptors});
    }
  }
  if (auto w = cut.takeWindowIfDue(t0 + map_until + 100)) windows.push_back({std::move(*w), cut.motionHint()});
  const DatasetInfo& i2 = (*ds2)->info();
  for (std::size_t i = 0; i < i2.frame_count; i += 10) {
    auto f = loadCameraFrame(**ds2, i);
    SE3 T_W_C;
    if (!f.ok() || !T_W_A || !gtCamera(i2, f->stamp, &T_W_C)) continue;
    auto fs = orb.extract(f->left);
    if (fs.ok()) queries_other.push_back({f->stamp, T_W_A->inverse() * T_W_C, fs->keypoints, fs->descriptors});
  }
  std::fprintf(stderr, "[mapuse] %zu windows, %zu later MH_01 queries, %zu MH_02 queries\n",
               windows.size(), queries_same.size(), queries_other.size());
  if (windows.empty() || !T_W_A) return std::fprintf(stderr, "no window / no tracking\n"), 1;
  // V1_01: all its windows, for the timing and selection parts only.
  std::vector<Window> windows_v1;
  {
    auto ds3 = Dataset::open((data_v1 / "V1_01_easy").string(), DatasetParams{});
    if (!ds3.ok()) return std::fprintf(stderr, "cannot open the rendered V1_01 data\n"), 1;
    const DatasetInfo& i3 = (*ds3)->info();
    Tracker tracker_v1(tp, i3.K, i3.baseline);
    WindowCut cut_v1(tracker_v1, tp.window);
    double last = 0;
    for (std::size_t i = 0; i < i3.frame_count; ++i) {
      auto f = loadCameraFrame(**ds3, i);
      if (!f.ok()) return std::fprintf(stderr, "%s\n", f.error().c_str()), 1;
      auto r = tracker_v1.feed(*f);
      if (!r.ok()) return std::fprintf(stderr, "%s\n", r.error().c_str()), 1;
      if (auto w = cut_v1.takeWindowIfDue(f->stamp)) windows_v1.push_back({std::move(*w), cut_v1.motionHint()});
      last = f->stamp;
    }
    if (auto w = cut_v1.takeWindowIfDue(last + 100)) windows_v1.push_back({std::move(*w), cut_v1.motionHint()});
  }
  std::fprintf(stderr, "[mapuse] %zu V1_01 windows\n", windows_v1.size());
  std::vector<const Window*> timed;
  std::vector<std::string> timed_seq;
  for (const Window& w : windows) timed.push_back(&w), timed_seq.push_back("MH_01_easy");
  for (const Window& w : windows_v1) timed.push_back(&w), timed_seq.push_back("V1_01_easy");

  auto size_fn = [](const Submap& s) { return encodedSizeUncompressed(s); };
  nlohmann::json out;
  out["bench"] = "mapuse";
  out["windows"] = windows.size();
  out["windows_timed"] = {{"MH_01_easy", windows.size()}, {"V1_01_easy", windows_v1.size()}};

  // 2. Timing on real windows, coordinator on (planning rate 30 kB/s).
  // One Distiller per strategy; the strategies take turns on each window, so
  // that a loaded machine affects every strategy alike.
  nlohmann::json timing_json;
  std::map<std::string, std::unique_ptr<distill::Distiller>> distillers;
  std::map<std::string, std::vector<double>> ms, sel_ms, trim_ms, objective, rounds;
  std::map<std::string, std::map<std::string, int>> status;
  std::map<std::string, std::map<std::string, double>> bytes, budget;
  std::map<std::string, int> over;
  std::vector<double> milp_vs_warm;  // milp objective / its greedy warm start's (same instance)
  for (const std::string& s : kStrategies) {
    distill::DistillParams dp;
    dp.strategy = s;
    auto d = distill::Distiller::create(dp, size_fn);
    if (!d.ok()) return std::fprintf(stderr, "%s\n", d.error().c_str()), 1;
    distillers[s] = std::move(*d);
  }
  for (std::size_t wi = 0; wi < timed.size(); ++wi) {
    const Window& w = *timed[wi];
    for (const std::string& s : kStrategies) {
      distill::CoordinatorInput in;
      in.bandwidth_Bps = 30000;
      distill::Distiller& d = *distillers[s];
      const auto a = std::chrono::steady_clock::now();
      const distill::DistillResult r = d.distill(w.submap, w.hint, in);
      ms[s].push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - a).count());
      sel_ms[s].push_back(r.report.time_select_ms);
      trim_ms[s].push_back(r.report.time_trim_ms);
      rounds[s].push_back(r.report.rounds);
      ++status[s][r.report.deferred ? "deferred" : r.report.selection_status];
      bytes[s][timed_seq[wi]] += double(r.report.bytes_actual);
      budget[s][timed_seq[wi]] += std::isfinite(r.report.budget_bytes) ? r.report.budget_bytes : 0;
      over[s] += r.report.over_budget;
      objective[s].push_back(r.report.objective);
      if (s == "milp" && r.report.greedy_objective > 0)
        milp_vs_warm.push_back(r.report.objective / r.report.greedy_objective);
    }
  }
  for (const std::string& s : kStrategies) {
    double b = 0, bb = 0;
    for (const auto& [seq, v] : bytes[s]) b += v, bb += budget[s][seq];
    timing_json[s] = {{"median_ms", percentile(ms[s], 50)}, {"p95_ms", percentile(ms[s], 95)},
                      {"select_ms", summary(sel_ms[s])}, {"trim_ms", summary(trim_ms[s])},
                      {"rounds", summary(rounds[s])}, {"status", status[s]},
                      {"bytes", b}, {"budget_bytes", bb}, {"bytes_per_sequence", bytes[s]},
                      {"budget_per_sequence", budget[s]}, {"over_budget", over[s]},
                      {"eq14_objective", summary(objective[s])}};
    std::fprintf(stderr, "[mapuse] timing %-14s median %7.1f ms  p95 %7.1f ms (select %6.1f / %6.1f, trim %6.1f)  bytes %8.0f / budget %8.0f\n",
                 s.c_str(), percentile(ms[s], 50), percentile(ms[s], 95), percentile(sel_ms[s], 50),
                 percentile(sel_ms[s], 95), percentile(trim_ms[s], 50), b, bb);
  }
  timing_json["milp_objective_over_its_greedy_warm_start"] = summary(milp_vs_warm);
  timing_json["ratio_to_greedy_logdet_median_ms"] = {};
  for (const std::string& s : kStrategies)
    timing_json["ratio_to_greedy_logdet_median_ms"][s] =
        percentile(ms[s], 50) / std::max(1e-9, percentile(ms["greedy_logdet"], 50));
  out["timing_30kBps"] = timing_json;

  // Selection alone, every strategy on the same Eq. 14 instance per window.
  {
    distill::DistillParams dp;
    std::map<std::string, std::vector<double>> t_ms, rel;
    std::map<std::string, std::map<std::string, int>> st;
    std::vector<double> milp_vs_warm_sel, milp_gap;
    int budget_violations = 0;
    for (const Window* w : timed) {
      const distill::TrimResult trim = distill::trimKeyframes(w->submap, dp.max_keyframes, dp);
      const Submap trimmed = distill::applyKeyframeTrim(w->submap, trim.kept);
      const distill::LandmarkScores sc = distill::computeScores(trimmed, w->hint, 0, dp);
      distill::SelectionProblem p = distill::buildSelectionProblem(
          trimmed, sc, 60, std::numeric_limits<double>::infinity(), dp.bytes_lm, dp.bytes_obs, dp);
      double all = 0;
      for (double b : p.bytes) all += b;
      p.budget = 0.4 * all;
      std::map<std::string, double> obj;
      for (const std::string& s : kStrategies) {
        if (s == "none") continue;
        auto sel = distill::makeLandmarkSelector(s, dp);
        const auto a = std::chrono::steady_clock::now();
        const distill::SelectionResult r = (*sel)->select(p);
        t_ms[s].push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - a).count());
        ++st[s][distill::toString(r.status)];
        obj[s] = r.objective;
        budget_violations += r.bytes > p.budget;
        if (s == "milp") {
          milp_vs_warm_sel.push_back(r.objective / r.greedy_objective);
          milp_gap.push_back(std::max(0.0, r.objective - r.lower_bound) / std::abs(r.objective));
        }
      }
      for (const auto& [s, o] : obj) rel[s].push_back(o / obj["greedy_logdet"]);
    }
    nlohmann::json sj;
    sj["instance"] = "trimmed to distill.max_keyframes, K = 60, landmark budget 40 % of all landmarks' bytes";
    for (const auto& [s, v] : t_ms)
      sj[s] = {{"select_ms", summary(v)}, {"status", st[s]},
               {"objective_over_greedy_logdet", summary(rel[s])}};
    sj["milp_objective_over_its_greedy_warm_start"] = summary(milp_vs_warm_sel);
    sj["milp_optimality_gap"] = summary(milp_gap);
    sj["budget_violations"] = budget_violations;
    out["selection_k60"] = sj;
    for (const auto& [s, v] : t_ms)
      std::fprintf(stderr, "[mapuse] select K=60 %-14s median %6.1f ms  p95 %6.1f ms  objective / greedy_logdet median %.3f min %.3f\n",
                   s.c_str(), percentile(v, 50), percentile(v, 95), percentile(rel[s], 50),
                   *std::min_element(rel[s].begin(), rel[s].end()));
  }
  if (timing_only) {
    const std::string text = out.dump(2);
    if (json_out.empty()) std::cout << text << "\n";
    else std::ofstream(json_out) << text << "\n";
    return 0;
  }

  // 3. Map usefulness per (K, strategy).
  nlohmann::json rows = nlohmann::json::array();
  std::fprintf(stderr, "%-14s %5s %9s %9s %8s %8s %8s %8s %7s %7s\n", "strategy", "K", "bytes",
               "landmarks", "recA", "recB", "strictA", "strictB", "inlA", "inlB");
  for (int K : kBudgets) {
    for (const std::string& s : kStrategies) {
      if (s == "none" && K != kBudgets.front()) continue;  // K does not apply
      distill::DistillParams dp;
      dp.strategy = s;
      dp.coordinator = false;
      dp.fixed_k = K;
      auto d = distill::Distiller::create(dp, size_fn);
      if (!d.ok()) return std::fprintf(stderr, "%s\n", d.error().c_str()), 1;
      std::vector<MapPoint> map;
      std::size_t bytes = 0;
      for (const Window& w : windows) {
        const distill::DistillResult r = (*d)->distill(w.submap, w.hint, distill::CoordinatorInput{});
        if (!r.report.ok || r.report.deferred) continue;
        bytes += encodedSizeUncompressed(r.submap);
        for (const Landmark& l : r.submap.landmarks) map.push_back({l.p_A, l.descriptor});
      }
      nlohmann::json row = {{"strategy", s}, {"K", s == "none" ? -1 : K}, {"bytes", bytes},
                            {"landmarks", map.size()}};
      for (const auto& [name, qs] : {std::pair{"same_robot_later", &queries_same},
                                     std::pair{"other_robot", &queries_other}}) {
        int ok = 0, strict = 0;
        std::vector<double> err, inl;
        for (const Query& q : *qs) {
          const Fix f = localise(map, q, i1.K);
          ok += f.ok;
          strict += f.strict;
          inl.push_back(f.inliers);
          if (f.ok) err.push_back(f.err_m);
        }
        const double n = std::max<double>(1.0, double(qs->size()));
        row[name] = {{"queries", qs->size()},
                     {"recall", double(ok) / n},
                     {"recall_strict", double(strict) / n},
                     {"median_inliers", percentile(inl, 50)},
                     {"median_error_m", err.empty() ? 0.0 : percentile(err, 50)}};
      }
      const auto& A = row["same_robot_later"];
      const auto& B = row["other_robot"];
      std::fprintf(stderr, "%-14s %5s %9zu %9zu %8.3f %8.3f %8.3f %8.3f %7.0f %7.0f\n", s.c_str(),
                   s == "none" ? "all" : std::to_string(K).c_str(), bytes, map.size(),
                   A["recall"].get<double>(), B["recall"].get<double>(),
                   A["recall_strict"].get<double>(), B["recall_strict"].get<double>(),
                   A["median_inliers"].get<double>(), B["median_inliers"].get<double>());
      rows.push_back(row);
    }
  }
  out["map_usefulness"] = rows;
  const std::string text = out.dump(2);
  if (json_out.empty()) {
    std::cout << text << "\n";
  } else {
    std::ofstream f(json_out);
    f << text << "\n";
    if (!f) return std::fprintf(stderr, "cannot write %s\n", json_out.c_str()), 1;
  }
  return 0;
}
