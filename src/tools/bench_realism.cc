// hermes_bench_realism: how close rendered frames come to real EuRoC frames.
// Compares the real V1_01 stereo clip (data/euroc_V1_01_micro) with
// renders along the V1_01 ground truth, default look and the realism preset,
// on the same statistics: temporal noise sigma (static pairs) and its fit
// sigma^2(I) = read + gain * I, mean grey level, gradient-magnitude histogram
// distance to the real frames' pooled histogram, FAST corners per frame (the
// ORB extractor's FAST threshold) and their median response. Per statistic it
// states whether the rendered median lies inside the real spread [min, max].
// The real clip is static (the drone sits on the ground), so whole real frames
// barely differ: the spread is taken over quarter frames (376 x 240), which
// sample the real image content; corner counts are scaled x4 to per frame.
// Prints a table (stderr) and JSON (stdout and --json FILE).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "hermes/core/image_stats.h"
#include "hermes/core/render/motion_blur.h"
#include "hermes/core/render/raycaster.h"
#include "hermes/core/render/rig.h"
#include "hermes/core/render/scene.h"
#include "hermes/core/render/settings.h"
#include "hermes/core/trajectory.h"
#include "hermes_help/hermes_bench_realism.h"  // tools/help/hermes_bench_realism.txt

using namespace hermes;
namespace fs = std::filesystem;

namespace {

const char* const kUsage = hermes_help::kText;

constexpr double kPairDt = 0.05;  // static pair: same pose, next frame time [s]

/// Per-unit values of every statistic, pooled over frames.
struct Stats {
  std::vector<double> noise_sigma;   ///< per static pair
  std::vector<double> mean_grey;     ///< per quarter
  std::vector<double> grad_dist;     ///< per quarter, to the real pooled histogram
  std::vector<double> corners;       ///< per quarter, x4 (per-frame scale)
  std::vector<double> response_med;  ///< per quarter
  std::vector<float> responses;      ///< pooled
  std::vector<std::vector<double>> grad_hist;  ///< per quarter
  NoiseFit noise;
  double blur_mean_px = 0;
  std::vector<cv::Mat> pair_a, pair_b;
};

std::vector<cv::Mat> quarters(const cv::Mat& img) {
  const int w = img.cols / 2, h = img.rows / 2;
  return {img(cv::Rect(0, 0, w, h)), img(cv::Rect(w, 0, w, h)), img(cv::Rect(0, h, w, h)),
          img(cv::Rect(w, h, w, h))};
}

void addFrame(const cv::Mat& img, int fast_threshold, Stats* s) {
  for (const cv::Mat& q : quarters(img)) {
    s->mean_grey.push_back(cv::mean(q)[0]);
    s->grad_hist.push_back(gradientHistogram(q));
    std::vector<float> r = fastResponses(q, fast_threshold);
    s->corners.push_back(4.0 * static_cast<double>(r.size()));
    std::vector<double> rd(r.begin(), r.end());
    s->response_med.push_back(quantile(rd, 0.5));
    s->responses.insert(s->responses.end(), r.begin(), r.end());
  }
}

void finish(const std::vector<double>& real_pooled, Stats* s) {
  s->noise = temporalNoise(s->pair_a, s->pair_b);
  for (std::size_t k = 0; k < s->pair_a.size(); ++k)
    s->noise_sigma.push_back(temporalNoise({s->pair_a[k]}, {s->pair_b[k]}).sigma);
  for (const auto& h : s->grad_hist) s->grad_dist.push_back(hellinger(h, real_pooled));
}

std::vector<double> pooled(const std::vector<std::vector<double>>& hists) {
  std::vector<double> p(hists.empty() ? 0 : hists[0].size(), 0.0);
  for (const auto& h : hists)
    for (std::size_t i = 0; i < h.size(); ++i) p[i] += h[i] / hists.size();
  return p;
}

Expected<std::vector<std::string>> listPngs(const std::string& dir) {
  std::vector<std::string> out;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec))
    if (e.path().extension() == ".png") out.push_back(e.path().string());
  if (ec) return Error{"cannot list " + dir + ": " + ec.message()};
  std::sort(out.begin(), out.end());
  return out;
}

/// Real frames: consecutive frames of each camera are static pairs.
Expected<Stats> realStats(const std::string& root, int fast_threshold) {
  Stats s;
  for (const char* cam : {"cam0", "cam1"}) {
    auto files = listPngs(root + "/mav0/" + cam + "/data");
    if (!files.ok()) return Error{files.error()};
    if (files->size() < 2) return Error{root + "/mav0/" + cam + "/data: fewer than 2 images"};
    cv::Mat prev;
    for (const std::string& f : *files) {
      cv::Mat img = cv::imread(f, cv::IMREAD_GRAYSCALE);
      if (img.empty()) return Error{"cannot read " + f};
      addFrame(img, fast_threshold, &s);
      if (!prev.empty()) {
        s.pair_a.push_back(prev);
        s.pair_b.push_back(img);
      }
      prev = img;
    }
    std::fprintf(stderr, "[realism] real %s: %zu frames\n", cam, files->size());
  }
  return s;
}

Expected<Stats> renderedStats(const Trajectory& traj, const render::RenderSettings& rs, int frames,
                              int fast_threshold, const std::string& label) {
  const PinholeRadtan cams[2] = {render::eurocCam0(), render::eurocCam1()};
  std::vector<Vec3> pos;
  render::appendRigPositions(traj, {cams[0].T_B_C, cams[1].T_B_C}, &pos);
  auto scene = render::buildScene(pos, rs.scene);
  if (!scene.ok()) return Error{scene.error()};
  Stats s;
  double blur_sum = 0;
  int blur_n = 0;
  const double t0 = traj.front().t + 1.0, span = traj.back().t - traj.front().t - 2.0;
  for (int c = 0; c < 2; ++c) {
    render::Raycaster rc(*scene, render::RayGrid::fromRadtan(cams[c]));
    render::Sensor sensor(rs.sensor, render::mixSeed(rs.scene.seed, 0xe0c), cams[c].K.width, cams[c].K.height);
    render::RenderOutput ro;
    cv::Mat blurred;
    for (int k = 0; k < frames; ++k) {
      const double t = t0 + span * k / std::max(1, frames - 1);
      render::BlurStats b;
      const cv::Mat& rad =
          render::renderExposure(rc, cams[c].K, traj, cams[c].T_B_C, t, rs.sensor, false, &ro, &blurred, &b);
      blur_sum += b.mean_px;
      ++blur_n;
      const cv::Mat img = sensor.expose(rad, t, c);
      addFrame(img, fast_threshold, &s);
      if (k % 4 == 0) {  // static pair: the same radiance exposed one frame later
        s.pair_a.push_back(img);
        s.pair_b.push_back(sensor.expose(rad, t + kPairDt, c));
      }
      if ((k + 1) % 10 == 0 || k + 1 == frames)
        std::fprintf(stderr, "\r[realism] %s cam%d: %d / %d frames   ", label.c_str(), c, k + 1, frames);
    }
    std::fprintf(stderr, "\n");
  }
  s.blur_mean_px = blur_n ? blur_sum / blur_n : 0;
  return s;
}

/// Motion blur along a trajectory (cam0, `frames` frames spread over it): the
/// per-frame mean smear and the longest one [px].
Expected<nlohmann::json> blurAlong(const std::string& path, const render::SensorParams& sensor, int frames) {
  auto traj = readTumTrajectory(path);
  if (!traj.ok()) return Error{traj.error()};
  if (traj->size() < 2) return Error{path + ": fewer than 2 poses"};
  const PinholeRadtan cam = render::eurocCam0();
  std::vector<Vec3> pos;
  render::appendRigPositions(*traj, {cam.T_B_C}, &pos);
  auto scene = render::buildScene(pos, render::SceneParams{});
  if (!scene.ok()) return Error{scene.error()};
  render::Raycaster rc(*scene, render::RayGrid::fromRadtan(cam));
  render::RenderOutput ro;
  cv::Mat blurred;
  std::vector<double> mean_px, max_px;
  const double t0 = traj->front().t + 1.0, span = traj->back().t - traj->front().t - 2.0;
  for (int k = 0; k < frames; ++k) {
    render::BlurStats b;
    render::renderExposure(rc, cam.K, *traj, cam.T_B_C, t0 + span * k / (frames - 1), sensor, false, &ro, &blurred, &b);
    mean_px.push_back(b.mean_px);
    max_px.push_back(b.max_px);
  }
  return nlohmann::json{{"frames", frames}, {"exposure_s", sensor.exposure_s},
                        {"mean_px", {{"median", quantile(mean_px, 0.5)}, {"p90", quantile(mean_px, 0.9)},
                                     {"max", quantile(mean_px, 1)}}},
                        {"longest_px", quantile(max_px, 1)}};
}

struct Row {
  std::string name, unit;
  const std::vector<double> Stats::*field;
};

}  // namespace

int main(int argc, char** argv) {
  std::string json_out, real = std::string(HERMES_DATA_DIR) + "/euroc_V1_01_micro";
  std::string traj_path = std::string(HERMES_TRAJECTORY_DIR) + "/V1_01_easy.txt";
  int frames = 40, fast_threshold = 20;
  std::vector<std::string> sets = {"render.realistic=true"};
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> const char* { return i + 1 < argc ? argv[++i] : nullptr; };
    const char* v = nullptr;
    if (a == "--help" || a == "-h") {
      std::fputs(kUsage, stdout);
      return 0;
    } else if ((a == "--json" || a == "--real" || a == "--trajectory" || a == "--frames" ||
                a == "--fast-threshold" || a == "--set") && (v = value())) {
      if (a == "--json") json_out = v;
      else if (a == "--real") real = v;
      else if (a == "--trajectory") traj_path = v;
      else if (a == "--frames") frames = std::atoi(v);
      else if (a == "--fast-threshold") fast_threshold = std::atoi(v);
      else sets.push_back(v);
    } else {
      std::fprintf(stderr, "hermes_bench_realism: bad argument '%s' (see --help)\n", a.c_str());
      return 2;
    }
  }
  if (frames < 4 || frames > 2000) {
    std::fprintf(stderr, "hermes_bench_realism: --frames must be in [4, 2000]\n");
    return 2;
  }
  if (fast_threshold < 1 || fast_threshold > 200) {
    std::fprintf(stderr, "hermes_bench_realism: --fast-threshold must be in [1, 200]\n");
    return 2;
  }
  cv::setNumThreads(1);
  auto realistic = render::readRenderSettings(Config(), sets);
  if (!realistic.ok()) {
    std::fprintf(stderr, "hermes_bench_realism: %s\n", realistic.error().c_str());
    return 2;
  }
  auto traj = readTumTrajectory(traj_path);
  if (!traj.ok() || traj->size() < 2) {
    std::fprintf(stderr, "hermes_bench_realism: --trajectory %s: %s\n", traj_path.c_str(),
                 traj.ok() ? "fewer than 2 poses" : traj.error().c_str());
    return 2;
  }
  const auto w0 = std::chrono::steady_clock::now();
  auto r = realStats(real, fast_threshold);
  if (!r.ok()) {
    std::fprintf(stderr, "hermes_bench_realism: %s\n", r.error().c_str());
    return 1;
  }
  const std::vector<double> ref = pooled(r->grad_hist);
  finish(ref, &*r);
  // Variants: the default look, the realism preset (with --set overrides) and
  // the preset without dark regions (the real V1_01 room is lit throughout).
  auto lit_sets = sets;
  lit_sets.push_back("render.scene.dark_regions=false");
  auto lit = render::readRenderSettings(Config(), lit_sets);
  if (!lit.ok()) {
    std::fprintf(stderr, "hermes_bench_realism: %s\n", lit.error().c_str());
    return 2;
  }
  struct Variant {
    std::string name;
    render::RenderSettings settings;
    Stats stats;
  };
  std::vector<Variant> variants = {{"rendered_default", render::RenderSettings{}, {}},
                                   {"rendered_realistic", *realistic, {}},
                                   {"rendered_realistic_lit", *lit, {}}};
  for (Variant& v : variants) {
    auto st = renderedStats(*traj, v.settings, frames, fast_threshold, v.name);
    if (!st.ok()) {
      std::fprintf(stderr, "hermes_bench_realism: %s\n", st.error().c_str());
      return 1;
    }
    v.stats = std::move(*st);
    finish(ref, &v.stats);
  }

  const std::vector<Row> rows = {
      {"noise_sigma", "grey levels (static pairs)", &Stats::noise_sigma},
      {"mean_grey", "grey levels", &Stats::mean_grey},
      {"gradient_hist_distance", "Hellinger to real pooled", &Stats::grad_dist},
      {"fast_corners_per_frame", "corners (quarter x4)", &Stats::corners},
      {"fast_response_median", "FAST score", &Stats::response_med},
  };
  nlohmann::json j;
  j["benchmark"] = "realism";
  j["real"] = real;
  j["trajectory"] = traj_path;
  j["frames_per_variant"] = frames;
  j["fast_threshold"] = fast_threshold;
  j["unit"] = "quarter frame (376x240); noise: per static frame pair";
  j["inside_rule"] = "rendered median within the real [min, max]";
  j["realistic_settings"] = sets;
  j["realistic_lit_settings"] = lit_sets;
  std::fprintf(stderr, "\n%-23s %-27s | %-8s %-8s %-8s |", "statistic", "unit", "real min", "real med", "real max");
  for (const Variant& v : variants) std::fprintf(stderr, " %-22s |", (v.name.substr(9) + " med (in)").c_str());
  std::fprintf(stderr, "\n");
  int inside_realistic = 0;
  for (const Row& row : rows) {
    const std::vector<double>& rv = (*r).*row.field;
    const double lo = quantile(rv, 0), hi = quantile(rv, 1);
    nlohmann::json e;
    e["unit"] = row.unit;
    e["real"] = {{"min", lo}, {"p05", quantile(rv, 0.05)}, {"median", quantile(rv, 0.5)},
                 {"p95", quantile(rv, 0.95)}, {"max", hi}, {"n", rv.size()}};
    std::fprintf(stderr, "%-23s %-27s | %8.3g %8.3g %8.3g |", row.name.c_str(), row.unit.c_str(), lo,
                 quantile(rv, 0.5), hi);
    for (const Variant& v : variants) {
      const std::vector<double>& vv = v.stats.*row.field;
      const double med = quantile(vv, 0.5);
      const bool in = med >= lo && med <= hi;
      int units_in = 0;
      for (double y : vv) units_in += y >= lo && y <= hi;
      e[v.name] = {{"min", quantile(vv, 0)}, {"median", med}, {"max", quantile(vv, 1)}, {"n", vv.size()},
                   {"inside_real_spread", in},
                   {"fraction_of_units_inside", vv.empty() ? 0.0 : double(units_in) / vv.size()}};
      std::fprintf(stderr, " %8.3g (%-3s)%8s |", med, in ? "yes" : "NO", "");
      if (v.name == "rendered_realistic") inside_realistic += in;
    }
    std::fprintf(stderr, "\n");
    j["stats"][row.name] = e;
  }
  auto fit = [](const Stats& s) {
    return nlohmann::json{{"sigma", s.noise.sigma}, {"read_var", s.noise.read_var},
                          {"photon_gain", s.noise.photon_gain}, {"pixels", s.noise.pixels},
                          {"bin_centre", s.noise.bin_centre}, {"bin_sigma", s.noise.bin_sigma}};
  };
  j["gradient_hist_pooled"]["bin_width"] = 2.0;
  j["gradient_hist_pooled"]["real"] = ref;
  j["noise_fit"]["real"] = fit(*r);
  std::fprintf(stderr, "noise fit sigma^2 = read + gain*I: real %.3f + %.4f I", r->noise.read_var, r->noise.photon_gain);
  for (const Variant& v : variants) {
    j["gradient_hist_pooled"][v.name] = pooled(v.stats.grad_hist);
    j["noise_fit"][v.name] = fit(v.stats);
    j["fast_response_ks_to_real"][v.name] = ksDistance(v.stats.responses, r->responses);
    j["motion_blur_mean_px"][v.name] = v.stats.blur_mean_px;
    std::fprintf(stderr, " | %s %.3f + %.4f I", v.name.substr(9).c_str(), v.stats.noise.read_var,
                 v.stats.noise.photon_gain);
  }
  std::fprintf(stderr, "\nFAST response KS distance to real:");
  for (const Variant& v : variants)
    std::fprintf(stderr, " %s %.3f", v.name.substr(9).c_str(), j["fast_response_ks_to_real"][v.name].get<double>());
  std::fprintf(stderr, "; realistic inside %d / %zu\n", inside_realistic, rows.size());
  j["realistic_inside"] = inside_realistic;
  if (realistic->sensor.motion_blur) {
    for (const char* stem : {"V1_01_easy", "V1_03_difficult", "MH_01_easy", "MH_04_difficult", "MH_05_difficult"}) {
      const std::string path = std::string(HERMES_TRAJECTORY_DIR) + "/" + stem + ".txt";
      if (!fs::exists(path)) continue;
      auto b = blurAlong(path, realistic->sensor, 30);
      if (!b.ok()) {
        std::fprintf(stderr, "hermes_bench_realism: %s\n", b.error().c_str());
        return 1;
      }
      j["motion_blur_along"][stem] = *b;
      std::fprintf(stderr, "motion blur %-16s: per-frame mean smear median %.2f px, p90 %.2f px; longest %.1f px\n",
                   stem, (*b)["mean_px"]["median"].get<double>(), (*b)["mean_px"]["p90"].get<double>(),
                   (*b)["longest_px"].get<double>());
    }
  }
  j["stats_count"] = rows.size();
  j["wall_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - w0).count();
  const std::string out = j.dump(2);
  std::puts(out.c_str());
  if (!json_out.empty()) {
    std::ofstream f(json_out);
    f << out << "\n";
    if (!f) {
      std::fprintf(stderr, "hermes_bench_realism: cannot write %s\n", json_out.c_str());
      return 1;
    }
  }
  return 0;
}
