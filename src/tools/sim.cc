// hermes_sim: renders stereo (EuRoC layout) or RGB-D (TUM layout) sequences
// along ground-truth trajectories inside one shared procedural scene.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <opencv2/core.hpp>

#include "hermes/core/render/dataset_writer.h"
#include "hermes/core/render/rig.h"
#include "hermes/core/render/scene.h"
#include "hermes/core/render/settings.h"
#include "hermes/core/trajectory.h"
#include "hermes_help/hermes_sim.h"  // tools/help/hermes_sim.txt

using namespace hermes;
namespace fs = std::filesystem;

namespace {
const char* const kUsage = hermes_help::kText;

int usageError(const std::string& msg) {
  std::fprintf(stderr, "hermes_sim: %s (see --help)\n", msg.c_str());
  return 2;
}

bool parseDouble(const std::string& s, double* v) {
  char* end = nullptr;
  *v = std::strtod(s.c_str(), &end);
  return end && *end == '\0' && !s.empty() && std::isfinite(*v);
}
}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> traj_paths;
  std::string out, format = "euroc";
  double start = 0, duration = -1, rate = -1, seed_d = 1, width = -1, height = -1, comp = 1;
  double jobs = 1;
  double poor_fraction = render::SceneParams().poor_fraction;
  bool noise = true, poor_given = false;
  std::string look;  // --realistic | --plain (empty: render.realistic from the config, default true)
  std::string config_path;
  std::vector<std::string> sets;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&](std::string* v) {
      if (i + 1 >= argc) return false;
      *v = argv[++i];
      return true;
    };
    std::string v;
    if (a == "--help" || a == "-h") {
      std::fputs(kUsage, stdout);
      return 0;
    } else if (a == "--no-noise") {
      noise = false;
    } else if (a == "--realistic" || a == "--plain") {
      if (!look.empty() && look != a) return usageError("--realistic and --plain exclude each other");
      look = a;
    } else if (a == "--config" || a == "--set") {
      if (!next(&v)) return usageError(a + " needs a value");
      if (a == "--config") config_path = v;
      else sets.push_back(v);
    } else if (a == "--trajectory" || a == "--out" || a == "--format" || a == "--start" ||
               a == "--duration" || a == "--rate" || a == "--seed" || a == "--width" ||
               a == "--height" || a == "--png-compression" || a == "--poor-fraction" || a == "--jobs") {
      if (!next(&v)) return usageError(a + " needs a value");
      if (a == "--trajectory") traj_paths.push_back(v);
      else if (a == "--out") out = v;
      else if (a == "--format") format = v;
      else {
        double x;
        if (!parseDouble(v, &x)) return usageError(a + ": not a number: '" + v + "'");
        if (a == "--start") start = x;
        else if (a == "--duration") duration = x;
        else if (a == "--rate") rate = x;
        else if (a == "--seed") seed_d = x;
        else if (a == "--width") width = x;
        else if (a == "--height") height = x;
        else if (a == "--poor-fraction") poor_fraction = x, poor_given = true;
        else if (a == "--jobs") jobs = x;
        else comp = x;
      }
    } else {
      return usageError("unknown argument '" + a + "'");
    }
  }
  if (traj_paths.empty()) return usageError("--trajectory is required");
  if (out.empty()) return usageError("--out is required");
  if (format != "euroc" && format != "tum") return usageError("--format must be euroc or tum, got '" + format + "'");
  if (start < 0) return usageError("--start must be >= 0");
  if (duration != -1 && duration <= 0) return usageError("--duration must be > 0");
  if (rate == -1) rate = format == "euroc" ? 20.0 : 30.0;
  if (!(rate > 0 && rate <= 1000)) return usageError("--rate must be in (0, 1000]");
  if (seed_d < 0 || seed_d != std::floor(seed_d)) return usageError("--seed must be a non-negative integer");
  if ((width == -1) != (height == -1)) return usageError("--width and --height go together");
  if (width != -1 && (width < 32 || height < 32 || width > 4096 || height > 4096 ||
                      width != std::floor(width) || height != std::floor(height)))
    return usageError("--width/--height must be integers in [32, 4096]");
  if (comp < 0 || comp > 9 || comp != std::floor(comp)) return usageError("--png-compression must be in 0..9");
  if (!(jobs >= 1 && jobs <= 64) || jobs != std::floor(jobs)) return usageError("--jobs must be an integer in [1, 64]");
  if (!(poor_fraction >= 0 && poor_fraction <= 1)) return usageError("--poor-fraction must be in [0, 1]");

  std::vector<Trajectory> trajs;
  std::vector<std::string> stems;
  for (const std::string& p : traj_paths) {
    auto t = readTumTrajectory(p);
    if (!t.ok()) return usageError("--trajectory " + p + ": " + t.error());
    if (t->size() < 2) return usageError("--trajectory " + p + ": fewer than 2 poses");
    if (start >= t->back().t - t->front().t) return usageError("--start is beyond the end of " + p);
    trajs.push_back(std::move(*t));
    std::string stem = fs::path(p).stem().string();
    for (const std::string& s : stems)
      if (s == stem) return usageError("--trajectory " + p + ": two trajectories share the stem '" + stem + "'");
    stems.push_back(stem);
  }

  PinholeRadtan cam0 = render::eurocCam0(), cam1 = render::eurocCam1();
  RgbdCamera rgbd = render::defaultRgbd();
  if (width != -1) {
    cam0.K = render::scaleIntrinsics(cam0.K, static_cast<int>(width), static_cast<int>(height));
    cam1.K = render::scaleIntrinsics(cam1.K, static_cast<int>(width), static_cast<int>(height));
    rgbd.K = render::scaleIntrinsics(rgbd.K, static_cast<int>(width), static_cast<int>(height));
  }
  cam0.rate_hz = cam1.rate_hz = rgbd.rate_hz = rate;

  // One scene around every camera position of every trajectory (whole trajectories,
  // independent of --start/--duration/--format, so windows of one seed share it).
  std::vector<Vec3> positions;
  for (const Trajectory& t : trajs) render::appendRigPositions(t, {cam0.T_B_C, cam1.T_B_C}, &positions);
  // Render settings: config file, --realistic / --plain, --set, then the plain flags.
  Config cfg;
  if (!config_path.empty()) {
    auto c = Config::fromFile(config_path);
    if (!c.ok()) return usageError("--config: " + c.error());
    cfg = *c;
  }
  if (!look.empty()) sets.insert(sets.begin(), look == "--plain" ? render::kPlainLook : "render.realistic=true");
  auto read = render::readRenderSettings(cfg, sets);
  if (!read.ok()) return usageError(read.error());
  render::RenderSettings settings = *read;
  if (!noise) settings.sensor.noise = false;
  render::SceneParams& sp = settings.scene;
  sp.seed = static_cast<std::uint64_t>(seed_d);
  if (poor_given) sp.poor_fraction = poor_fraction;
  const auto t_scene = std::chrono::steady_clock::now();
  auto scene = render::buildScene(positions, sp);
  if (!scene.ok()) {
    std::fprintf(stderr, "hermes_sim: %s\n", scene.error().c_str());
    return 1;
  }
  std::fprintf(stderr, "hermes_sim: scene built in %.2f s: %zu objects, %zu textures, %zu photographs",
               std::chrono::duration<double>(std::chrono::steady_clock::now() - t_scene).count(),
               scene->objects.size(), scene->textures.size(), scene->photo_names.size());
  if (scene->photo_names.empty())
    std::fprintf(stderr, " (no photographs found in %s: procedural textures only)", scene->photo_folder.c_str());
  std::fprintf(stderr, "\n");
  std::error_code ec;
  fs::create_directories(out, ec);
  {
    std::ofstream f(out + "/scene.json");
    f << render::sceneToJson(*scene) << "\n";
    if (!f) {
      std::fprintf(stderr, "hermes_sim: cannot write %s/scene.json\n", out.c_str());
      return 1;
    }
  }

  {
    std::ofstream f(out + "/render_config.yaml");
    f << settings.fingerprint();
    if (!f) {
      std::fprintf(stderr, "hermes_sim: cannot write %s/render_config.yaml\n", out.c_str());
      return 1;
    }
  }

  render::SequenceSpec spec;
  spec.start_s = start;
  spec.duration_s = duration;
  spec.rate_hz = rate;
  spec.seed = sp.seed;
  spec.png_compression = static_cast<int>(comp);
  spec.sensor = settings.sensor;
  // One sequence per worker: each has its own ray casters, movers and sensor
  // (seeded per robot), the scene is only read, so the output does not depend
  // on --jobs.
  const std::size_t workers = std::min<std::size_t>(static_cast<std::size_t>(jobs), trajs.size());
  const char* unit = format == "euroc" ? "pairs" : "frames";
  std::mutex print;
  std::atomic<std::size_t> next_seq{0};
  std::atomic<bool> failed{false};
  auto worker = [&]() {
    for (std::size_t i = next_seq++; i < trajs.size() && !failed; i = next_seq++) {
      const std::string dir = out + "/" + stems[i];
      const std::string& label = stems[i];
      auto progress = [&](int done, int total, double secs) {
        // One robot: a progress line rewritten in place; several: a line every 100 frames.
        const bool show = workers == 1 ? (done % 10 == 0 || done == total) : (done % 100 == 0 || done == total);
        if (!show) return;
        std::lock_guard<std::mutex> lock(print);
        std::fprintf(stderr, "%s[%s] %d / %d frames, %.1f %s/s   %s", workers == 1 ? "\r" : "", label.c_str(), done,
                     total, done / std::max(secs, 1e-9), unit, workers == 1 && done != total ? "" : "\n");
      };
      render::SequenceSpec mine = spec;
      mine.seed = render::mixSeed(sp.seed, i);  // sensor noise differs between robots
      auto st = format == "euroc" ? render::writeEurocSequence(dir, *scene, trajs[i], cam0, cam1, mine, progress)
                                  : render::writeTumSequence(dir, *scene, trajs[i], rgbd, mine, progress);
      std::lock_guard<std::mutex> lock(print);
      if (!st.ok()) {
        std::fprintf(stderr, "hermes_sim: %s\n", st.error().c_str());
        failed = true;
        return;
      }
      std::fprintf(stderr, "[%s] render %.1f %s/s, render+write %.1f %s/s\n", label.c_str(),
                   st->frames / std::max(st->render_s, 1e-9), unit,
                   st->frames / std::max(st->render_s + st->write_s, 1e-9), unit);
    }
  };
  std::vector<std::thread> pool;
  for (std::size_t w = 1; w < workers; ++w) pool.emplace_back(worker);
  worker();
  for (std::thread& t : pool) t.join();
  if (failed) return 1;
  return 0;
}
