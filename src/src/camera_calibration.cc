// CameraCalibration: validation, format detection, Hermes camera files and
// EuRoC pairs. Kalibr and ROS camera_info: calibration_ros_kalibr.cc.
#include "hermes/core/camera_calibration.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <sstream>

#include "calib_yaml.h"
#include "dataset_text.h"
#include "hermes/core/euroc_dataset.h"
#include "hermes/core/tum_dataset.h"

namespace fs = std::filesystem;
using namespace hermes::calib_yaml;  // NOLINT: private helpers

namespace hermes {
namespace {

bool sameValue(double a, double b) { return std::abs(a - b) <= 1e-9 * std::max(1.0, std::abs(a)); }

Status checkCamera(const PinholeRadtan& c, const std::string& name, int width, int height) {
  const PinholeIntrinsics& K = c.K;
  if (K.width != width || K.height != height)
    return Error{name + " camera is " + std::to_string(K.width) + "x" + std::to_string(K.height) +
                 ", calibration says " + std::to_string(width) + "x" + std::to_string(height)};
  if (!(K.fx > 0 && K.fy > 0 && std::isfinite(K.fx) && std::isfinite(K.fy) &&
        std::isfinite(K.cx) && std::isfinite(K.cy)))
    return Error{name + " camera: fx, fy must be positive and finite"};
  for (double d : c.dist)
    if (!std::isfinite(d)) return Error{name + " camera: distortion is not finite"};
  if (c.model == DistortionModel::kEquidistant && (c.dist[4] != 0 || c.dist[5] != 0 ||
                                                   c.dist[6] != 0 || c.dist[7] != 0))
    return Error{name + " camera: equidistant takes 4 coefficients"};
  if (!(c.rate_hz >= 0)) return Error{name + " camera: rate_hz must be >= 0"};
  return Status::Ok();
}

Status checkStereo(const CameraCalibration& c) {
  for (const auto& [cam, name] : {std::pair{&c.stereo.left, "left"}, {&c.stereo.right, "right"}})
    if (Status s = checkCamera(*cam, name, c.width, c.height); !s) return s;
  if (c.stereo.left.model != c.stereo.right.model)
    return Error{"left and right distortion models differ"};
  const SE3 T_Cl_Cr = c.stereo.T_Cl_Cr();
  const Vec3 t = T_Cl_Cr.translation();
  if (!(t.norm() > 1e-6)) return Error{"stereo baseline is zero"};
  if (!c.rectified) return Status::Ok();
  const PinholeIntrinsics &Kl = c.stereo.left.K, &Kr = c.stereo.right.K;
  if (c.stereo.left.hasDistortion() || c.stereo.right.hasDistortion())
    return Error{"rectified cameras must have no distortion"};
  if (!sameValue(Kl.fx, Kr.fx) || !sameValue(Kl.fy, Kr.fy) || !sameValue(Kl.cy, Kr.cy))
    return Error{"rectified cameras must share fx, fy and cy"};
  if (rotationAngle(T_Cl_Cr.rotation()) > 1e-6 || !(t.x() > 0) ||
      std::hypot(t.y(), t.z()) > 1e-6 * t.x())
    return Error{"rectified cameras must be parallel with the right one at +x of the left"};
  return Status::Ok();
}

// One camera block of a Hermes file (model, intrinsics, distortion, T_B_C).
Status readHermesCamera(const YAML::Node& root, const std::string& key, const Where& w, int width,
                        int height, double rate_hz, PinholeRadtan* cam) {
  auto m = subMap(root, key, w);
  if (!m) return Error{m.error()};
  const Where in = w.child(key);
  auto model = text(*m, "model", in);
  if (!model) return Error{model.error()};
  if (*model != "pinhole") return in.bad(get(*m, "model"), "model", "must be pinhole");
  auto intr = numbers(*m, "intrinsics", in, {4});
  if (!intr) return Error{intr.error()};
  cam->K = PinholeIntrinsics{(*intr)[0], (*intr)[1], (*intr)[2], (*intr)[3], width, height};
  if (!(cam->K.fx > 0 && cam->K.fy > 0))
    return in.bad(get(*m, "intrinsics"), "intrinsics",
                  "needs positive focal lengths fx, fy (ICL-NUIM publishes fy -480 for its "
                  "y-up renderer: give 480, see config/cameras/icl_nuim.yaml)");
  auto dmodel = text(*m, "distortion_model", in);
  if (!dmodel) return Error{dmodel.error()};
  std::vector<double> coeffs;
  if (*dmodel != "none" || get(*m, "distortion")) {
    auto d = numbers(*m, "distortion", in, {});
    if (!d) return Error{d.error()};
    coeffs = *d;
  }
  if (Status s = setDistortion(*dmodel, coeffs, *m, "distortion_model", "distortion", in, cam); !s)
    return s;
  if (get(*m, "T_B_C")) {
    auto T = transform(*m, "T_B_C", in);
    if (!T) return Error{T.error()};
    cam->T_B_C = *T;
  }
  cam->rate_hz = rate_hz;
  return Status::Ok();
}

void writeCamera(std::ostream& o, const char* key, const PinholeRadtan& c) {
  o << key << ":\n  model: pinhole\n  distortion_model: " << distortionName(c)
    << "\n  intrinsics: [" << c.K.fx << ", " << c.K.fy << ", " << c.K.cx << ", " << c.K.cy
    << "]  # fx, fy, cx, cy [px]\n";
  if (c.hasDistortion() || c.model == DistortionModel::kEquidistant) {
    o << "  distortion: [";
    for (int i = 0; i < c.distortionCount(); ++i) o << (i ? ", " : "") << c.dist[i];
    o << "]\n";
  }
  o << "  T_B_C: [";  // body <- camera, row-major
  const Mat4 T = c.T_B_C.matrix();
  for (int i = 0; i < 16; ++i) o << T(i / 4, i % 4) << (i < 15 ? ", " : "");
  o << "]  # body <- camera, row-major 4x4\n";
}

// A camera_info file's partner: "left" <-> "right" swapped in the file name.
Expected<std::pair<std::string, std::string>> cameraInfoPair(const std::string& path) {
  const fs::path p(path);
  const std::string name = p.filename().string();
  for (const auto& [from, to] : {std::pair{"left", "right"}, {"right", "left"}}) {
    const auto at = name.rfind(from);
    if (at == std::string::npos) continue;
    std::string other = name;
    other.replace(at, std::string(from).size(), to);
    const std::string partner = (p.parent_path() / other).string();
    if (!fs::exists(partner))
      return Error{path + ": ROS camera_info pair is incomplete: '" + partner + "' does not exist"};
    if (std::string(from) == "left") return std::pair{path, partner};
    return std::pair{partner, path};
  }
  return Error{path + ": a ROS camera_info file describes one camera; Hermes reads a stereo "
               "pair whose file names differ by left/right (e.g. left.yaml, right.yaml)"};
}

std::string availableNames(const std::string& dir) {
  std::vector<std::string> names;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec))
    if (e.path().extension() == ".yaml") names.push_back(e.path().stem().string());
  std::sort(names.begin(), names.end());
  std::string s;
  for (const auto& n : names) s += (s.empty() ? "" : ", ") + n;
  return s.empty() ? "none" : s;
}

}  // namespace

Status CameraCalibration::validate() const {
  Status s;
  if (width <= 0 || height <= 0)
    s = Error{"image size " + std::to_string(width) + "x" + std::to_string(height) + " is empty"};
  else if (kind == Kind::kStereo)
    s = checkStereo(*this);
  else if (!(rgbd.depth_scale > 0 && std::isfinite(rgbd.depth_scale)))
    s = Error{"depth_scale must be positive"};
  else
    s = checkCamera(rgbd.colourCamera(), "RGB-D", width, height);
  if (!s) return Error{source + ": " + s.error()};
  return s;
}

std::string CameraCalibration::summary() const {
  std::ostringstream o;
  o.precision(6);
  if (kind == Kind::kStereo) {
    o << (rectified ? "rectified stereo" : "stereo") << " (" << format << ") " << width << "x"
      << height << " " << distortionName(stereo.left) << " fx " << stereo.left.K.fx
      << " baseline " << stereo.T_Cl_Cr().translation().norm() << " m";
  } else {
    o << "rgbd (" << format << ") " << width << "x" << height << " "
      << distortionName(rgbd.colourCamera()) << " fx " << rgbd.K.fx << " depth_scale "
      << rgbd.depth_scale;
  }
  o << " from " << source;
  return o.str();
}

Expected<CameraCalibration> readHermesCameraFile(const std::string& path) {
  auto root = loadMap(path);
  if (!root) return Error{root.error()};
  const Where w{path, ""};
  CameraCalibration c;
  c.format = "hermes";
  c.source = path;
  auto kind = text(*root, "kind", w);
  if (!kind) return Error{kind.error()};
  if (Status s = resolution(*root, "resolution", w, &c.width, &c.height); !s)
    return Error{s.error()};
  auto rate = number(*root, "rate_hz", w, 0.0);
  if (!rate) return Error{rate.error()};
  if (*rate < 0) return w.bad(get(*root, "rate_hz"), "rate_hz", "must be >= 0");
  if (*kind == "stereo") {
    c.kind = CameraCalibration::Kind::kStereo;
    if (const YAML::Node r = get(*root, "rectified")) {
      try {
        c.rectified = r.as<bool>();
      } catch (const YAML::Exception&) {
        return w.bad(r, "rectified", "must be true or false");
      }
    }
    for (const auto& [key, cam] : {std::pair{"left", &c.stereo.left}, {"right", &c.stereo.right}})
      if (Status s = readHermesCamera(*root, key, w, c.width, c.height, *rate, cam); !s)
        return Error{s.error()};
  } else if (*kind == "rgbd") {
    c.kind = CameraCalibration::Kind::kRgbd;
    auto scale = number(*root, "depth_scale", w);
    if (!scale) return Error{scale.error()};
    if (!(*scale > 0)) return w.bad(get(*root, "depth_scale"), "depth_scale", "must be positive");
    PinholeRadtan cam;
    if (Status s = readHermesCamera(*root, "camera", w, c.width, c.height, *rate, &cam); !s)
      return Error{s.error()};
    if (cam.model != DistortionModel::kRadtan || cam.distortionCount() > 5)
      return w.child("camera").bad(get(get(*root, "camera"), "distortion_model"),
                                   "distortion_model",
                                   "must be none, radtan or plumb_bob for an RGB-D camera");
    c.rgbd.K = cam.K;
    std::copy(cam.dist.begin(), cam.dist.begin() + 5, c.rgbd.dist.begin());
    c.rgbd.T_B_C = cam.T_B_C;
    c.rgbd.rate_hz = *rate;
    c.rgbd.depth_scale = *scale;
  } else {
    return w.bad(get(*root, "kind"), "kind", "must be stereo or rgbd (is '" + *kind + "')");
  }
  if (Status s = c.validate(); !s) return Error{s.error()};
  return c;
}

Status writeHermesCameraFile(const std::string& path, const CameraCalibration& c,
                             const std::string& comment) {
  std::ostringstream o;
  o.precision(17);
  std::istringstream lines(comment);
  for (std::string line; std::getline(lines, line);) o << "# " << line << "\n";
  const bool stereo = c.kind == CameraCalibration::Kind::kStereo;
  const double rate = stereo ? c.stereo.left.rate_hz : c.rgbd.rate_hz;
  o << "kind: " << (stereo ? "stereo" : "rgbd") << "\nresolution: [" << c.width << ", "
    << c.height << "]  # width, height [px]\nrate_hz: " << rate << "  # [Hz], 0 = unknown\n";
  if (stereo) {
    o << "rectified: " << (c.rectified ? "true" : "false") << "\n";
    writeCamera(o, "left", c.stereo.left);
    writeCamera(o, "right", c.stereo.right);
  } else {
    o << "depth_scale: " << c.rgbd.depth_scale << "  # depth PNG value per metre\n";
    writeCamera(o, "camera", c.rgbd.colourCamera());
  }
  return dataset_text::writeTextFile(path, o.str());
}

Expected<CameraCalibration> readEurocCalibration(const std::string& cam0_yaml,
                                                 const std::string& cam1_yaml) {
  auto l = readEurocCameraYaml(cam0_yaml);
  if (!l) return Error{l.error()};
  auto r = readEurocCameraYaml(cam1_yaml);
  if (!r) return Error{r.error()};
  CameraCalibration c;
  c.format = "euroc";
  c.source = cam0_yaml + " + " + cam1_yaml;
  c.stereo = StereoRig{*l, *r};
  c.width = l->K.width;
  c.height = l->K.height;
  if (Status s = c.validate(); !s) return Error{s.error()};
  return c;
}

Expected<CameraCalibration> loadCameraCalibration(const std::string& name_or_path,
                                                  const std::string& cameras_dir) {
  std::error_code ec;
  std::string path = name_or_path;
  const bool bare = name_or_path.find('/') == std::string::npos &&
                    fs::path(name_or_path).extension().empty() && !fs::exists(name_or_path, ec);
  if (bare) {
    path = (fs::path(cameras_dir) / (name_or_path + ".yaml")).string();
    if (!fs::exists(path, ec))
      return Error{"camera '" + name_or_path + "': no file '" + path +
                   "' (available: " + availableNames(cameras_dir) + ")"};
  }
  if (fs::is_directory(path, ec)) {
    fs::path mav0(path);
    if (fs::is_directory(mav0 / "mav0", ec)) mav0 /= "mav0";
    const fs::path c0 = mav0 / "cam0" / "sensor.yaml", c1 = mav0 / "cam1" / "sensor.yaml";
    if (fs::exists(c0, ec) && fs::exists(c1, ec))
      return readEurocCalibration(c0.string(), c1.string());
    const fs::path l = fs::path(path) / "left.yaml", r = fs::path(path) / "right.yaml";
    if (fs::exists(l, ec) && fs::exists(r, ec)) return readCameraInfoPair(l.string(), r.string());
    const fs::path tum = fs::path(path) / "camera.yaml";
    if (fs::exists(tum, ec)) return readTumCalibration(tum.string());
    return Error{"'" + path + "': folder holds neither cam0/ + cam1/ sensor.yaml (EuRoC) nor " +
                 "left.yaml + right.yaml (ROS camera_info) nor camera.yaml (TUM)"};
  }
  if (!fs::exists(path, ec)) return Error{"calibration file '" + path + "' does not exist"};
  auto root = loadMap(path);
  if (!root) return Error{root.error()};
  if (get(*root, "kind")) return readHermesCameraFile(path);
  if (get(*root, "cam0")) return readKalibrCamchain(path);
  if (get(*root, "camera_matrix")) {
    auto pair = cameraInfoPair(path);
    if (!pair) return Error{pair.error()};
    return readCameraInfoPair(pair->first, pair->second);
  }
  if (get(*root, "T_BS")) {
    // .../camN/sensor.yaml: the pair is .../cam0/ and .../cam1/.
    const fs::path seq = fs::absolute(path, ec).parent_path().parent_path();
    const std::string file = fs::path(path).filename().string();
    return readEurocCalibration((seq / "cam0" / file).string(), (seq / "cam1" / file).string());
  }
  if (get(*root, "fx") && get(*root, "depth_scale")) return readTumCalibration(path);
  return Error{path + ": unknown calibration format (no key 'kind' (Hermes camera file), "
               "'cam0' (Kalibr camchain), 'camera_matrix' (ROS camera_info), 'T_BS' "
               "(EuRoC sensor.yaml) or 'fx' + 'depth_scale' (TUM camera.yaml))"};
}

Expected<CameraCalibration> readTumCalibration(const std::string& camera_yaml) {
  auto cam = readTumCameraYaml(camera_yaml);
  if (!cam) return Error{cam.error()};
  CameraCalibration c;
  c.kind = CameraCalibration::Kind::kRgbd;
  c.format = "tum";
  c.source = camera_yaml;
  c.rgbd = *cam;
  c.width = cam->K.width;
  c.height = cam->K.height;
  if (Status s = c.validate(); !s) return Error{s.error()};
  return c;
}

}  // namespace hermes
