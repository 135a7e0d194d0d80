// hermes_bench_mapuse (`./hermes bench mapuse`): distillation on the agent's
// REAL 5-s windows and how useful the distilled maps are (paper Fig. 15).
//   1. Renders MH_01 and MH_02 in one hall (cached), runs the stereo front end
//      (Tracker) on MH_01 and collects its windows.
//   2. Timing: every strategy distils every window with the coordinator on at a
//      fixed planning rate: per-window time median/p95, solver status counts,
//      bytes vs budget.
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
#include <map>
#include <string>
#include <tuple>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>

#include "hermes/agent/dataset_feed.h"
#include "hermes/agent/orb_extractor.h"
#include "hermes/agent/tracker.h"
#include "hermes/core/evaluation.h"
#include "hermes/core/metrics.h"
#include "hermes/core/wire_format.h"
#include "hermes/distill/distiller.h"

using namespace hermes;
namespace fs = std::filesystem;

namespace {

const char* kUsage =
    "usage: hermes_bench_mapuse [--duration S] [--map-until S] [--cache DIR] [--json FILE]\n"
    "  --duration S   rendered seconds per robot (default 40)\n"
    "  --map-until S  MH_01 windows before this time build the map (default 25); later\n"
    "                 MH_01 frames and all MH_02 frames are localised against it\n"
    "  --cache DIR    rendered data (default data_cache/bench_mapuse)\n";

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
  std::string cache = std::string(HERMES_SOURCE_DIR) + "/data_cache/bench_mapuse", json_out;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "hermes_bench_mapuse: %s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--help" || a == "-h") return std::cout << kUsage, 0;
    if (a == "--duration") duration = std::atof(next().c_str());
    else if (a == "--map-until") map_until = std::atof(next().c_str());
    else if (a == "--cache") cache = next();
    else if (a == "--json") json_out = next();
    else return std::fprintf(stderr, "hermes_bench_mapuse: unknown argument '%s'\n", a.c_str()), 2;
  }
  if (!(duration > map_until + 5) || !(map_until > 5))
    return std::fprintf(stderr, "hermes_bench_mapuse: need 5 < --map-until < --duration - 5\n"), 2;

  char key[64];
  std::snprintf(key, sizeof key, "d%g", duration);
  const fs::path data = fs::path(cache) / key;
  if (!fs::exists(data / "done")) {
    std::fprintf(stderr, "[mapuse] rendering MH_01 + MH_02 (%g s) into %s\n", duration, data.c_str());
    fs::remove_all(data);
    const fs::path bin = fs::read_symlink("/proc/self/exe").parent_path();
    char cmd[2048];
    std::snprintf(cmd, sizeof cmd,
                  "%s --trajectory %s/config/trajectories/MH_01_easy.txt --trajectory "
                  "%s/config/trajectories/MH_02_easy.txt --out %s --duration %g --seed 1 >/dev/null 2>&1",
                  (bin / "hermes_sim").c_str(), HERMES_SOURCE_DIR, HERMES_SOURCE_DIR, data.c_str(),
                  duration);
    if (std::system(cmd) != 0) return std::fprintf(stderr, "rendering failed: %s\n", cmd), 1;
    std::ofstream(data / "done") << "ok\n";
  }

  // 1. Front end on MH_01: windows, and the map frame A (first camera pose).
  auto ds1 = Dataset::open((data / "MH_01_easy").string(), DatasetParams{});
  auto ds2 = Dataset::open((data / "MH_02_easy").string(), DatasetParams{});
  if (!ds1.ok() || !ds2.ok()) return std::fprintf(stderr, "cannot open the rendered data\n"), 1;
  const DatasetInfo& i1 = (*ds1)->info();
  TrackerParams tp;
  Tracker tracker(tp, i1.K, i1.baseline);
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
      if (auto w = tracker.takeWindowIfDue(f->stamp)) windows.push_back({std::move(*w), tracker.motionHint()});
    } else if (i % 5 == 0) {
      auto fs = orb.extract(f->left);
      SE3 T_W_C;
      if (fs.ok() && T_W_A && gtCamera(i1, f->stamp, &T_W_C))
        queries_same.push_back({rel, T_W_A->inverse() * T_W_C, fs->keypoints, fs->descriptors});
    }
  }
  if (auto w = tracker.takeWindowIfDue(t0 + map_until + 100)) windows.push_back({std::move(*w), tracker.motionHint()});
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

  auto size_fn = [](const Submap& s) { return encodedSizeUncompressed(s); };
  nlohmann::json out;
  out["bench"] = "mapuse";
  out["windows"] = windows.size();

  // 2. Timing on real windows, coordinator on (planning rate 30 kB/s).
  nlohmann::json timing_json;
  for (const std::string& s : kStrategies) {
    distill::DistillParams dp;
    dp.strategy = s;
    auto d = distill::Distiller::create(dp, size_fn);
    if (!d.ok()) return std::fprintf(stderr, "%s\n", d.error().c_str()), 1;
    std::vector<double> ms;
    std::map<std::string, int> status;
    double bytes = 0, budget = 0;
    int over = 0;
    for (const Window& w : windows) {
      distill::CoordinatorInput in;
      in.bandwidth_Bps = 30000;
      const auto a = std::chrono::steady_clock::now();
      const distill::DistillResult r = (*d)->distill(w.submap, w.hint, in);
      ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - a).count());
      ++status[r.report.deferred ? "deferred" : r.report.selection_status];
      bytes += double(r.report.bytes_actual);
      budget += std::isfinite(r.report.budget_bytes) ? r.report.budget_bytes : 0;
      over += r.report.over_budget;
    }
    timing_json[s] = {{"median_ms", percentile(ms, 50)}, {"p95_ms", percentile(ms, 95)},
                      {"status", status}, {"bytes", bytes}, {"budget_bytes", budget},
                      {"over_budget", over}};
    std::fprintf(stderr, "[mapuse] timing %-14s median %7.1f ms  p95 %7.1f ms  bytes %8.0f / budget %8.0f\n",
                 s.c_str(), percentile(ms, 50), percentile(ms, 95), bytes, budget);
  }
  out["timing_30kBps"] = timing_json;

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
