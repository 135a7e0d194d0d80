// hermes_bench_datasets: dataset reading and stereo rectification speed and
// accuracy on a real folder (default: the EuRoC micro sequence). Prints JSON.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/features2d.hpp>

#include "hermes/core/dataset.h"
#include "hermes/core/stopwatch.h"
#include "hermes_help/hermes_bench_datasets.h"  // tools/help/hermes_bench_datasets.txt

using namespace hermes;

namespace {

using Clock = std::chrono::steady_clock;
double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(p * (v.size() - 1) + 0.5))];
}

// Synthetic check: random points seen by both real distorted cameras.
nlohmann::json geometryCheck(const RectifiedStereo& rs) {
  const StereoRig& rig = rs.rig;
  const SE3 T_Cr_Cl = rig.T_Cl_Cr().inverse();
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> ux(-1, 1), uz(0.5, 30.0);
  std::vector<double> row, disp;
  const auto t0 = Clock::now();
  for (int i = 0; i < 200000 && row.size() < 10000; ++i) {
    const double z = uz(rng);
    const Vec3 p(ux(rng) * 0.8 * z, ux(rng) * 0.55 * z, z);
    Vec2 a, b;
    if (!rig.left.project(p, &a) || !rig.right.project(T_Cr_Cl * p, &b)) continue;
    if (!rig.left.K.inImage(a) || !rig.right.K.inImage(b)) continue;
    const Vec2 ra = rs.rectifyPointLeft(a), rb = rs.rectifyPointRight(b);
    row.push_back(std::abs(ra.y() - rb.y()));
    disp.push_back(std::abs((ra.x() - rb.x()) - rs.disparityAtDepth((rs.R_rect_left * p).z())));
  }
  const double us_per_point = 1000.0 * msSince(t0) / (2.0 * row.size());
  return {{"points", row.size()},
          {"row_error_px_max", percentile(row, 1.0)},
          {"disparity_error_px_max", percentile(disp, 1.0)},
          {"rectify_point_us", us_per_point}};
}

// Real check: ORB matches between rectified images should share rows.
void rowStats(const cv::Mat& l, const cv::Mat& r, std::vector<double>* dy) {
  static auto orb = cv::ORB::create(1500);
  std::vector<cv::KeyPoint> kl, kr;
  cv::Mat dl, dr;
  orb->detectAndCompute(l, cv::noArray(), kl, dl);
  orb->detectAndCompute(r, cv::noArray(), kr, dr);
  if (dl.empty() || dr.empty()) return;
  cv::BFMatcher bf(cv::NORM_HAMMING, true);
  std::vector<cv::DMatch> m;
  bf.match(dl, dr, m);
  for (const auto& x : m)
    if (x.distance < 40) dy->push_back(std::abs(kl[x.queryIdx].pt.y - kr[x.trainIdx].pt.y));
}

// The shipped micro EuRoC sequence (data/README.md).
std::string defaultDataset() { return std::string(HERMES_DATA_DIR) + "/euroc_V1_01_micro"; }

}  // namespace

int main(int argc, char** argv) {
  std::string dir = defaultDataset(), json_out;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--help" || a == "-h") {
      std::fputs(hermes_help::kText, stdout);
      return 0;
    }
    if ((a == "--dataset" || a == "--json") && i + 1 < argc) {
      (a == "--dataset" ? dir : json_out) = argv[++i];
    } else {
      std::fprintf(stderr, "hermes_bench_datasets: unknown or incomplete argument '%s'\n", a.c_str());
      return 2;
    }
  }
  if (dir.empty()) {
    std::fprintf(stderr, "hermes_bench_datasets: no default dataset found, give --dataset DIR\n");
    return 2;
  }
  auto t0 = Clock::now();
  auto ds = Dataset::open(dir);
  if (!ds) {
    std::fprintf(stderr, "hermes_bench_datasets: %s\n", ds.error().c_str());
    return 1;
  }
  const double open_ms = msSince(t0);
  const DatasetInfo& info = (*ds)->info();
  nlohmann::json j;
  j["dataset"] = dir;
  j["kind"] = toString(info.kind);
  j["frames"] = info.frame_count;
  j["groundtruth_poses"] = info.groundtruth.size();
  j["warnings"] = info.warnings;
  j["open_ms"] = open_ms;

  std::vector<double> load_ms;
  std::vector<double> dy_rect, dy_raw;
  if (info.kind == DatasetKind::kEuroc) {
    const EurocDataset& e = *(*ds)->euroc();
    t0 = Clock::now();
    auto rs = rectify(*info.stereo);
    const double rect_ms = msSince(t0);
    if (!rs) {
      std::fprintf(stderr, "hermes_bench_datasets: %s\n", rs.error().c_str());
      return 1;
    }
    j["baseline_m"] = rs->baseline;
    j["rectified_fx"] = rs->K.fx;
    j["rectify_setup_ms"] = rect_ms;
    j["geometry"] = geometryCheck(*rs);
    std::vector<double> remap_ms;
    for (std::size_t i = 0; i < e.size(); ++i) {
      t0 = Clock::now();
      auto f = e.load(i);
      load_ms.push_back(msSince(t0));
      if (!f) {
        std::fprintf(stderr, "hermes_bench_datasets: %s\n", f.error().c_str());
        return 1;
      }
      cv::Mat l, r;
      t0 = Clock::now();
      rs->rectifyImages(f->left, f->right, &l, &r);
      remap_ms.push_back(msSince(t0));
      if (i % 10 == 0) {
        rowStats(l, r, &dy_rect);
        rowStats(f->left, f->right, &dy_raw);
      }
    }
    j["remap_pair_ms_median"] = percentile(remap_ms, 0.5);
    auto frac = [](const std::vector<double>& v, double tol) {
      return v.empty() ? 0.0
                       : static_cast<double>(std::count_if(v.begin(), v.end(),
                                                           [&](double x) { return x <= tol; })) /
                             v.size();
    };
    j["orb_matches"] = dy_rect.size();
    j["orb_rows_within_1px_rectified"] = frac(dy_rect, 1.0);
    j["orb_rows_within_1px_raw"] = frac(dy_raw, 1.0);
    j["orb_dy_p75_px_rectified"] = percentile(dy_rect, 0.75);
    j["orb_dy_p75_px_raw"] = percentile(dy_raw, 0.75);
  } else {
    for (std::size_t i = 0; i < (*ds)->size(); ++i) {
      t0 = Clock::now();
      auto f = (*ds)->loadRgbd(i);
      load_ms.push_back(msSince(t0));
      if (!f) {
        std::fprintf(stderr, "hermes_bench_datasets: %s\n", f.error().c_str());
        return 1;
      }
    }
  }
  j["load_frame_ms_median"] = percentile(load_ms, 0.5);
  j["load_frame_ms_p95"] = percentile(load_ms, 0.95);
  const std::string text = j.dump(2);
  std::printf("%s\n", text.c_str());
  if (!json_out.empty()) {
    std::ofstream out(json_out);
    out << text << "\n";
    if (!out) {
      std::fprintf(stderr, "hermes_bench_datasets: cannot write '%s'\n", json_out.c_str());
      return 1;
    }
  }
  return 0;
}
