// EuRoC ASL and TUM RGB-D writers for rendered sequences.
#include "hermes/core/render/dataset_writer.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <sstream>

#include <opencv2/imgcodecs.hpp>

#include "hermes/core/render/motion_blur.h"
#include "hermes/core/render/raycaster.h"

namespace hermes {
namespace render {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {
double secondsSince(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

Status makeDirs(const std::string& d) {
  std::error_code ec;
  fs::create_directories(d, ec);
  if (ec) return Error{"cannot create directory " + d + ": " + ec.message()};
  return Status::Ok();
}

Status checkStream(const std::ofstream& f, const std::string& path) {
  if (!f) return Error{"cannot write " + path};
  return Status::Ok();
}

SE3 poseAt(const Trajectory& traj, std::int64_t ns) {
  double t = std::clamp(ns * 1e-9, traj.front().t, traj.back().t);
  SE3 T;
  interpolatePose(traj, t, &T);
  return T;
}

std::string tumStamp(std::int64_t ns) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%lld.%06lld", static_cast<long long>(ns / 1000000000),
                static_cast<long long>((ns % 1000000000) / 1000));
  return buf;
}

Status checkSpec(const Trajectory& traj, const SequenceSpec& spec) {
  if (traj.size() < 2) return Error{"trajectory has fewer than 2 poses"};
  if (!(spec.rate_hz > 0 && spec.rate_hz <= 1000)) return Error{"rate must be in (0, 1000] Hz"};
  if (!(spec.start_s >= 0)) return Error{"start must be >= 0 s"};
  if (spec.png_compression < 0 || spec.png_compression > 9) return Error{"png_compression must be in [0, 9]"};
  return spec.sensor.validate();
}
}  // namespace

std::vector<std::int64_t> frameTimesNs(const Trajectory& traj, const SequenceSpec& spec) {
  std::vector<std::int64_t> out;
  if (traj.size() < 2 || !(spec.rate_hz > 0)) return out;
  const std::int64_t first = std::llround(traj.front().t * 1e9);
  const std::int64_t last = std::llround(traj.back().t * 1e9);
  const std::int64_t base = first + std::llround(spec.start_s * 1e9);
  for (std::int64_t k = 0;; ++k) {
    const double rel = k / spec.rate_hz;
    if (spec.duration_s >= 0 && rel >= spec.duration_s - 1e-9) break;
    const std::int64_t ns = base + std::llround(rel * 1e9);
    if (ns > last) break;
    out.push_back(ns);
  }
  return out;
}

std::string eurocSensorYaml(const PinholeRadtan& cam, const std::string& comment) {
  std::ostringstream s;
  s << std::setprecision(12);
  const Mat4 T = cam.T_B_C.matrix();
  s << "%YAML:1.0\n# General sensor definitions.\nsensor_type: camera\ncomment: " << comment
    << "\n\n# Sensor extrinsics wrt. the body-frame.\nT_BS:\n  cols: 4\n  rows: 4\n  data: [";
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) s << T(r, c) << (r == 3 && c == 3 ? "]\n" : ", ");
    if (r < 3) s << "\n         ";
  }
  s << "\n# Camera specific definitions.\nrate_hz: " << cam.rate_hz << "\nresolution: [" << cam.K.width
    << ", " << cam.K.height << "]\ncamera_model: pinhole\nintrinsics: [" << cam.K.fx << ", " << cam.K.fy
    << ", " << cam.K.cx << ", " << cam.K.cy << "] #fu, fv, cu, cv\n"
    << "distortion_model: radial-tangential\ndistortion_coefficients: [" << cam.dist[0] << ", "
    << cam.dist[1] << ", " << cam.dist[2] << ", " << cam.dist[3] << "]\n";
  return s.str();
}

Expected<WriteStats> writeEurocSequence(const std::string& dir, const Scene& scene,
                                        const Trajectory& traj, const PinholeRadtan& cam0,
                                        const PinholeRadtan& cam1, const SequenceSpec& spec,
                                        const Progress& progress) {
  if (Status st = checkSpec(traj, spec); !st) return Error{dir + ": " + st.error()};
  const std::string mav = dir + "/mav0";
  for (const std::string& d : {mav + "/cam0/data", mav + "/cam1/data", mav + "/state_groundtruth_estimate0"})
    if (Status st = makeDirs(d); !st) return Error{st.error()};
  const PinholeRadtan* cams[2] = {&cam0, &cam1};
  for (int c = 0; c < 2; ++c) {
    PinholeRadtan cc = *cams[c];
    cc.rate_hz = spec.rate_hz;
    const std::string p = mav + "/cam" + std::to_string(c) + "/sensor.yaml";
    std::ofstream f(p);
    f << eurocSensorYaml(cc, "Hermes synthetic render of VI-Sensor cam" + std::to_string(c));
    if (Status st = checkStream(f, p); !st) return Error{st.error()};
  }
  {
    std::ofstream f(mav + "/body.yaml");
    f << "%YAML:1.0\ncomment: Hermes synthetic body (EuRoC IMU frame); poses in "
         "state_groundtruth_estimate0 are T_W_B\n";
    if (Status st = checkStream(f, mav + "/body.yaml"); !st) return Error{st.error()};
  }
  const std::vector<std::int64_t> times = frameTimesNs(traj, spec);
  if (times.empty()) return Error{dir + ": no frame inside the trajectory for the requested start/duration"};

  Raycaster rc0(scene, RayGrid::fromRadtan(cam0)), rc1(scene, RayGrid::fromRadtan(cam1));
  const Raycaster* rcs[2] = {&rc0, &rc1};
  Sensor sensor(spec.sensor, mixSeed(spec.seed, 0xe0c), cam0.K.width, cam0.K.height);
  Sensor sensor1(spec.sensor, mixSeed(spec.seed, 0xe0c), cam1.K.width, cam1.K.height);
  const Sensor* sensors[2] = {&sensor, &sensor1};
  std::ofstream csv0(mav + "/cam0/data.csv"), csv1(mav + "/cam1/data.csv");
  std::ofstream gt(mav + "/state_groundtruth_estimate0/data.csv");
  std::ofstream* csvs[2] = {&csv0, &csv1};
  csv0 << "#timestamp [ns],filename\n";
  csv1 << "#timestamp [ns],filename\n";
  gt << "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], "
        "q_RS_z [], v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1], b_w_RS_S_x [rad s^-1], "
        "b_w_RS_S_y [rad s^-1], b_w_RS_S_z [rad s^-1], b_a_RS_S_x [m s^-2], b_a_RS_S_y [m s^-2], "
        "b_a_RS_S_z [m s^-2]\n";
  gt << std::setprecision(10);
  const std::vector<int> png = {cv::IMWRITE_PNG_COMPRESSION, spec.png_compression};
  WriteStats stats;
  RenderOutput ro;
  cv::Mat blurred;
  for (std::size_t k = 0; k < times.size(); ++k) {
    const std::int64_t ns = times[k];
    const SE3 T_W_B = poseAt(traj, ns);
    rc0.placeMovers(ns * 1e-9);
    rc1.placeMovers(ns * 1e-9);
    for (int c = 0; c < 2; ++c) {
      auto t0 = Clock::now();
      const cv::Mat& radiance = renderExposure(*rcs[c], cams[c]->K, traj, cams[c]->T_B_C, ns * 1e-9,
                                               spec.sensor, false, &ro, &blurred);
      const cv::Mat img = sensors[c]->expose(radiance, ns * 1e-9, c);
      stats.render_s += secondsSince(t0);
      t0 = Clock::now();
      const std::string name = std::to_string(ns) + ".png";
      const std::string path = mav + "/cam" + std::to_string(c) + "/data/" + name;
      if (!cv::imwrite(path, img, png)) return Error{"cannot write image " + path};
      *csvs[c] << ns << "," << name << "\n";
      stats.write_s += secondsSince(t0);
    }
    const Quat& q = T_W_B.quat();
    const Vec3& p = T_W_B.translation();
    gt << ns << "," << p.x() << "," << p.y() << "," << p.z() << "," << q.w() << "," << q.x() << ","
       << q.y() << "," << q.z() << ",0,0,0,0,0,0,0,0,0\n";
    ++stats.frames;
    if (progress) progress(stats.frames, static_cast<int>(times.size()), stats.render_s + stats.write_s);
  }
  for (auto* f : {&csv0, &csv1, &gt})
    if (!*f) return Error{"cannot write csv files under " + mav};
  return stats;
}

Expected<WriteStats> writeTumSequence(const std::string& dir, const Scene& scene,
                                      const Trajectory& traj, const RgbdCamera& cam,
                                      const SequenceSpec& spec, const Progress& progress) {
  if (Status st = checkSpec(traj, spec); !st) return Error{dir + ": " + st.error()};
  for (const std::string& d : {dir + "/rgb", dir + "/depth"})
    if (Status st = makeDirs(d); !st) return Error{st.error()};
  {
    std::ofstream f(dir + "/camera.yaml");
    f << std::setprecision(12) << "# Hermes synthetic RGB-D camera (pinhole, no distortion)\n"
      << "fx: " << cam.K.fx << "\nfy: " << cam.K.fy << "\ncx: " << cam.K.cx << "\ncy: " << cam.K.cy
      << "\nwidth: " << cam.K.width << "\nheight: " << cam.K.height
      << "\ndepth_scale: " << cam.depth_scale << "  # depth png value per metre\n"
      << "rate_hz: " << spec.rate_hz << "\n";
    if (Status st = checkStream(f, dir + "/camera.yaml"); !st) return Error{st.error()};
  }
  const std::vector<std::int64_t> times = frameTimesNs(traj, spec);
  if (times.empty()) return Error{dir + ": no frame inside the trajectory for the requested start/duration"};
  Raycaster rc(scene, RayGrid::fromPinhole(cam.K));
  Sensor sensor(spec.sensor, mixSeed(spec.seed, 0x7b0), cam.K.width, cam.K.height);
  std::ofstream rgb_txt(dir + "/rgb.txt"), depth_txt(dir + "/depth.txt"), gt(dir + "/groundtruth.txt");
  rgb_txt << "# color images (8-bit grey)\n# timestamp filename\n";
  depth_txt << "# depth maps (16-bit, metres * depth_scale, 0 = invalid)\n# timestamp filename\n";
  gt << "# ground truth of the CAMERA frame (T_W_C = T_W_B * T_B_C)\n# timestamp tx ty tz qx qy qz qw\n";
  gt << std::setprecision(10);
  const std::vector<int> png = {cv::IMWRITE_PNG_COMPRESSION, spec.png_compression};
  WriteStats stats;
  RenderOutput ro;
  cv::Mat blurred;
  cv::Mat depth16(cam.K.height, cam.K.width, CV_16U);
  for (std::size_t k = 0; k < times.size(); ++k) {
    const std::int64_t ns = times[k];
    const SE3 T_W_C = poseAt(traj, ns) * cam.T_B_C;
    rc.placeMovers(ns * 1e-9);
    auto t0 = Clock::now();
    const cv::Mat& radiance =
        renderExposure(rc, cam.K, traj, cam.T_B_C, ns * 1e-9, spec.sensor, /*want_depth=*/true, &ro, &blurred);
    const cv::Mat img = sensor.expose(radiance, ns * 1e-9, 0);
    for (int v = 0; v < depth16.rows; ++v) {
      const float* z = ro.depth.ptr<float>(v);
      auto* d = depth16.ptr<std::uint16_t>(v);
      for (int u = 0; u < depth16.cols; ++u) {
        const double q = std::round(z[u] * cam.depth_scale);
        d[u] = (q > 0 && q <= 65535) ? static_cast<std::uint16_t>(q) : 0;
      }
    }
    stats.render_s += secondsSince(t0);
    t0 = Clock::now();
    const std::string stamp = tumStamp(ns);
    if (!cv::imwrite(dir + "/rgb/" + stamp + ".png", img, png)) return Error{"cannot write " + dir + "/rgb/" + stamp + ".png"};
    if (!cv::imwrite(dir + "/depth/" + stamp + ".png", depth16, png))
      return Error{"cannot write " + dir + "/depth/" + stamp + ".png"};
    rgb_txt << stamp << " rgb/" << stamp << ".png\n";
    depth_txt << stamp << " depth/" << stamp << ".png\n";
    const Quat& q = T_W_C.quat();
    const Vec3& p = T_W_C.translation();
    gt << stamp << " " << p.x() << " " << p.y() << " " << p.z() << " " << q.x() << " " << q.y() << " "
       << q.z() << " " << q.w() << "\n";
    stats.write_s += secondsSince(t0);
    ++stats.frames;
    if (progress) progress(stats.frames, static_cast<int>(times.size()), stats.render_s + stats.write_s);
  }
  for (auto* f : {&rgb_txt, &depth_txt, &gt})
    if (!*f) return Error{"cannot write index files under " + dir};
  return stats;
}

}  // namespace render
}  // namespace hermes
