// hermes_bench_render: speed of the synthetic renderer on ONE core, along the
// real MH_01_easy ground truth. Prints JSON (stdout and --json FILE).
// Reports wall-clock and thread-CPU rates (the CPU rate is what one dedicated
// core would achieve; wall time suffers on a shared machine).
#include <ctime>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "hermes/core/render/dataset_writer.h"
#include "hermes/core/render/motion_blur.h"
#include "hermes/core/render/settings.h"
#include "hermes/core/render/raycaster.h"
#include "hermes/core/render/rig.h"
#include "hermes/core/render/scene.h"
#include "hermes/core/render/sensor.h"
#include "hermes/core/trajectory.h"
#include "hermes_help/hermes_bench_render.h"  // tools/help/hermes_bench_render.txt

using namespace hermes;

namespace {
double cpuNow() {
  timespec ts;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}
double wallNow() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}
}  // namespace

int main(int argc, char** argv) {
  std::string json_out, traj_path = HERMES_TRAJECTORY_DIR "/MH_01_easy.txt";
  int frames = 60;
  std::vector<std::string> sets;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--help") {
      std::fputs(hermes_help::kText, stdout);
      return 0;
    } else if (a == "--realistic") sets.push_back("render.realistic=true");
    else if (a == "--plain") sets.push_back(render::kPlainLook);
    else if (a == "--set" && i + 1 < argc) sets.push_back(argv[++i]);
    else if (a == "--json" && i + 1 < argc) json_out = argv[++i];
    else if (a == "--frames" && i + 1 < argc) frames = std::max(1, std::atoi(argv[++i]));
    else if (a == "--trajectory" && i + 1 < argc) traj_path = argv[++i];
    else {
      std::fprintf(stderr, "hermes_bench_render: unknown argument '%s'\n", a.c_str());
      return 2;
    }
  }
  cv::setNumThreads(1);
  auto settings = render::readRenderSettings(Config(), sets);
  if (!settings.ok()) {
    std::fprintf(stderr, "hermes_bench_render: %s\n", settings.error().c_str());
    return 2;
  }
  const render::SensorParams& sp = settings->sensor;
  auto traj = readTumTrajectory(traj_path);
  if (!traj.ok()) {
    std::fprintf(stderr, "hermes_bench_render: %s\n", traj.error().c_str());
    return 2;
  }
  const PinholeRadtan cam0 = render::eurocCam0(), cam1 = render::eurocCam1();
  const RgbdCamera rgbd = render::defaultRgbd();
  std::vector<Vec3> pos;
  for (const StampedPose& p : *traj) pos.push_back(p.T_W_B.translation());
  double w0 = wallNow(), c0 = cpuNow();
  auto scene = render::buildScene(pos, settings->scene);
  if (!scene.ok()) {
    std::fprintf(stderr, "hermes_bench_render: %s\n", scene.error().c_str());
    return 1;
  }
  const double scene_cpu = cpuNow() - c0, scene_wall = wallNow() - w0;
  w0 = wallNow();
  c0 = cpuNow();
  render::Raycaster rc0(*scene, render::RayGrid::fromRadtan(cam0));
  render::Raycaster rc1(*scene, render::RayGrid::fromRadtan(cam1));
  render::Raycaster rcd(*scene, render::RayGrid::fromPinhole(rgbd.K));
  const double rays_cpu = cpuNow() - c0;
  render::Sensor sensor(sp, 1, 752, 480), sensor_d(sp, 2, 640, 480);
  cv::Mat blurred;

  // Frames spread over the whole trajectory (varied views, 0.5 s apart).
  std::vector<double> times;
  for (int k = 0; k < frames; ++k) times.push_back(traj->front().t + 2.0 + 0.5 * k);
  const std::string tmp = std::filesystem::temp_directory_path().string() + "/hermes_bench_render";
  std::filesystem::create_directories(tmp);
  const std::vector<int> png = {cv::IMWRITE_PNG_COMPRESSION, 1};
  double r_cpu = 0, r_wall = 0, wr_cpu = 0, wr_wall = 0, d_cpu = 0, d_wall = 0;
  render::RenderOutput ro;
  std::size_t bytes = 0;
  for (double t : times) {
    SE3 T_W_B;
    if (!interpolatePose(*traj, std::min(t, traj->back().t), &T_W_B)) continue;
    double w = wallNow(), c = cpuNow();
    cv::Mat i0 = sensor.expose(render::renderExposure(rc0, cam0.K, *traj, cam0.T_B_C, t, sp, false, &ro, &blurred), t, 0);
    cv::Mat i1 = sensor.expose(render::renderExposure(rc1, cam1.K, *traj, cam1.T_B_C, t, sp, false, &ro, &blurred), t, 1);
    r_cpu += cpuNow() - c;
    r_wall += wallNow() - w;
    w = wallNow();
    c = cpuNow();
    cv::imwrite(tmp + "/cam0.png", i0, png);
    cv::imwrite(tmp + "/cam1.png", i1, png);
    wr_cpu += cpuNow() - c;
    wr_wall += wallNow() - w;
    bytes += std::filesystem::file_size(tmp + "/cam0.png");
    w = wallNow();
    c = cpuNow();
    cv::Mat g = sensor_d.expose(render::renderExposure(rcd, rgbd.K, *traj, rgbd.T_B_C, t, sp, true, &ro, &blurred), t, 0);
    cv::Mat d16;
    ro.depth.convertTo(d16, CV_16U, rgbd.depth_scale);
    cv::imwrite(tmp + "/rgb.png", g, png);
    cv::imwrite(tmp + "/depth.png", d16, png);
    d_cpu += cpuNow() - c;
    d_wall += wallNow() - w;
  }
  std::filesystem::remove_all(tmp);
  const double n = static_cast<double>(times.size());
  nlohmann::json j;
  j["benchmark"] = "render";
  j["trajectory"] = traj_path;
  j["frames"] = times.size();
  j["resolution"] = {752, 480};
  j["threads"] = 1;
  j["settings"] = sets;
  j["scene_build_s"] = {{"cpu", scene_cpu}, {"wall", scene_wall}};
  j["ray_grid_build_s_cpu"] = rays_cpu;
  j["stereo_pairs_per_s_render_only"] = {{"cpu", n / r_cpu}, {"wall", n / r_wall}};
  j["stereo_pairs_per_s_render_and_png"] = {{"cpu", n / (r_cpu + wr_cpu)}, {"wall", n / (r_wall + wr_wall)}};
  j["rgbd_frames_per_s_640x480_render_and_png"] = {{"cpu", n / d_cpu}, {"wall", n / d_wall}};
  j["png_kB_per_image"] = bytes / n / 1024.0;
  j["textures"] = scene->textures.size();
  j["photos"] = scene->photo_names.size();
  const std::string s = j.dump(2);
  std::puts(s.c_str());
  if (!json_out.empty()) std::ofstream(json_out) << s << "\n";
  return 0;
}
