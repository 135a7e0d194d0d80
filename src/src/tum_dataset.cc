#include "hermes/core/tum_dataset.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <sstream>
#include <tuple>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "dataset_text.h"
#include "hermes/core/camera_calibration.h"

namespace fs = std::filesystem;
using namespace hermes::dataset_text;  // NOLINT: private helpers

namespace hermes {
namespace {

Status requireDouble(const YAML::Node& root, const std::string& key, const std::string& path,
                     double* out, bool required = true) {
  const YAML::Node n = root[key];
  if (!n) return required ? Status(Error{path + ": missing key '" + key + "'"}) : Status::Ok();
  try {
    *out = n.as<double>();
  } catch (const YAML::Exception&) {
    return Error{path + ":" + std::to_string(n.Mark().line + 1) + ": '" + key +
                 "' must be a number"};
  }
  if (!std::isfinite(*out)) return Error{path + ": '" + key + "' is not finite"};
  return Status::Ok();
}

/// True when every stamp is a whole number and they rise by whole steps: frame indices.
bool frameIndexStamps(const std::vector<double>& stamps) {
  if (stamps.size() < 2) return !stamps.empty() && stamps[0] == std::floor(stamps[0]);
  for (double t : stamps)
    if (t != std::floor(t)) return false;
  return true;
}

struct AssociationRow {
  double t_rgb = 0, t_depth = 0;
  std::string rgb, depth;
};

/// associations.txt: `t depth t rgb` (ICL-NUIM) or `t rgb t depth` (TUM's associate.py),
/// told apart by which file name holds "depth".
Expected<std::vector<AssociationRow>> readAssociations(const std::string& path) {
  std::vector<AssociationRow> rows;
  Status s = forEachDataLine(path, "association list", [&](const std::string& t, const std::string& where) -> Status {
    std::istringstream ss(t);
    std::string s1, f1, s2, f2, extra;
    ss >> s1 >> f1 >> s2 >> f2;
    double t1 = 0, t2 = 0;
    if (f2.empty() || (ss >> extra) || !parseDouble(s1, &t1) || !parseDouble(s2, &t2))
      return Error{where + ": expected 'stamp file stamp file'"};
    const bool depth_first = f1.find("depth") != std::string::npos;
    if (depth_first == (f2.find("depth") != std::string::npos))
      return Error{where + ": exactly one of the two files must be a depth image (name holds 'depth')"};
    AssociationRow r;
    if (depth_first) r = {t2, t1, f2, f1};
    else r = {t1, t2, f1, f2};
    if (!rows.empty() && r.t_rgb <= rows.back().t_rgb) return Error{where + ": stamps must increase"};
    rows.push_back(std::move(r));
    return Status::Ok();
  });
  if (!s) return Error{s.error()};
  if (rows.empty()) return Error{"association list '" + path + "' holds no rows"};
  return rows;
}

/// The folder's ICL-NUIM ground truth: `*.gt.freiburg` in it, else in its parent.
std::string findFreiburgGroundTruth(const fs::path& root) {
  std::error_code ec;
  for (const fs::path& d : {root, fs::absolute(root, ec).parent_path()}) {
    std::vector<std::string> found;
    for (const auto& e : fs::directory_iterator(d, ec))
      if (e.is_regular_file(ec) && isIclNuimGroundTruthName(e.path().string()))
        found.push_back(e.path().string());
    std::sort(found.begin(), found.end());
    if (!found.empty()) return found.front();
  }
  return "";
}

}  // namespace

bool isIclNuimGroundTruthName(const std::string& path) {
  const std::string tail = ".gt.freiburg";
  return path.size() > tail.size() && path.compare(path.size() - tail.size(), tail.size(), tail) == 0;
}

Expected<Trajectory> readIclNuimGroundTruth(const std::string& path, double rate_hz) {
  if (!(rate_hz > 0)) return Error{"ICL-NUIM ground truth '" + path + "': rate must be positive"};
  auto traj = readTumTrajectory(path);
  if (!traj) return Error{traj.error()};
  std::vector<double> stamps;
  for (const auto& p : *traj) stamps.push_back(p.t);
  const bool indices = frameIndexStamps(stamps);
  const Mat3 M = Vec3(1, -1, 1).asDiagonal();
  for (auto& p : *traj) {
    if (indices) p.t /= rate_hz;
    p.T_W_B = SE3(Mat3(M * p.T_W_B.rotation() * M), Vec3(M * p.T_W_B.translation()));
  }
  return traj;
}

RgbdCamera iclNuimDefaultCamera() {
  RgbdCamera c;
  c.K.fx = 481.20;
  c.K.fy = 480.00;
  c.K.cx = 319.5;
  c.K.cy = 239.5;
  c.K.width = 640;
  c.K.height = 480;
  c.depth_scale = 5000.0;
  c.rate_hz = 30.0;
  return c;
}

Expected<RgbdCamera> readTumCameraYaml(const std::string& path) {
  auto text = readTextFile(path);
  if (!text) return Error{text.error()};
  if (text->rfind("%YAML", 0) == 0) (*text)[0] = '#';  // tolerate OpenCV's "%YAML:1.0"
  YAML::Node root;
  try {
    root = YAML::Load(*text);
  } catch (const YAML::Exception& e) {
    return Error{path + ":" + std::to_string(e.mark.line + 1) + ": YAML error: " + e.msg};
  }
  if (!root.IsMap()) return Error{path + ": not a YAML map"};
  if (root["kind"]) {  // a Hermes camera file (config/cameras/*.yaml) copied in
    auto calib = readHermesCameraFile(path);
    if (!calib) return Error{calib.error()};
    if (calib->kind != CameraCalibration::Kind::kRgbd)
      return Error{path + ": key 'kind' must be rgbd for a TUM / ICL-NUIM folder"};
    return calib->rgbd;
  }
  RgbdCamera cam;
  if (root["camera_model"]) {
    const std::string model = root["camera_model"].Scalar();
    if (model != "pinhole")
      return Error{path + ": unsupported camera_model '" + model + "' (supported: pinhole)"};
  }
  double w = 0, h = 0;
  for (auto [key, out] : {std::pair<const char*, double*>{"fx", &cam.K.fx}, {"fy", &cam.K.fy},
                          {"cx", &cam.K.cx}, {"cy", &cam.K.cy}, {"width", &w}, {"height", &h}}) {
    Status s = requireDouble(root, key, path, out);
    if (!s) return Error{s.error()};
  }
  if (!(cam.K.fx > 0 && cam.K.fy > 0)) return Error{path + ": fx and fy must be positive"};
  if (!(w >= 1 && h >= 1 && w == std::floor(w) && h == std::floor(h) && w < 1e5 && h < 1e5))
    return Error{path + ": width and height must be positive integers"};
  cam.K.width = static_cast<int>(w);
  cam.K.height = static_cast<int>(h);
  Status s = requireDouble(root, "depth_scale", path, &cam.depth_scale, false);
  if (!s) return Error{s.error()};
  if (!(cam.depth_scale > 0)) return Error{path + ": depth_scale must be positive"};
  // Optional plumb_bob distortion of the colour camera (absent = undistorted).
  const char* kDist[5] = {"k1", "k2", "p1", "p2", "k3"};
  for (int i = 0; i < 5; ++i) {
    s = requireDouble(root, kDist[i], path, &cam.dist[i], false);
    if (!s) return Error{s.error()};
  }
  s = requireDouble(root, "rate_hz", path, &cam.rate_hz, false);
  if (!s) return Error{s.error()};
  if (!(cam.rate_hz > 0)) return Error{path + ": rate_hz must be positive"};
  if (const YAML::Node t = root["T_B_C"]) {
    if (!t.IsSequence() || t.size() != 16)
      return Error{path + ": 'T_B_C' must be a list of 16 numbers (row-major 4x4)"};
    Mat4 T;
    try {
      for (int i = 0; i < 16; ++i) T(i / 4, i % 4) = t[i].as<double>();
    } catch (const YAML::Exception& e) {
      return Error{path + ":" + std::to_string(e.mark.line + 1) + ": 'T_B_C' holds a non-number"};
    }
    const Mat3 R = T.topLeftCorner<3, 3>();
    if (!T.allFinite() || (R.transpose() * R - Mat3::Identity()).norm() > 1e-4 ||
        R.determinant() < 0 || (T.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).norm() > 1e-9)
      return Error{path + ": 'T_B_C' is not a rigid transform"};
    cam.T_B_C = SE3(T);
  }
  return cam;
}

Status writeTumCameraYaml(const std::string& path, const RgbdCamera& cam) {
  std::ostringstream o;
  o.precision(17);
  o << "# Hermes RGB-D camera (pinhole, "
    << (cam.hasDistortion() ? "plumb_bob distortion" : "no distortion")
    << ")\ncamera_model: pinhole\n"
    << "fx: " << cam.K.fx << "  # [px]\nfy: " << cam.K.fy << "\ncx: " << cam.K.cx
    << "\ncy: " << cam.K.cy << "\n";
  if (cam.hasDistortion())
    o << "k1: " << cam.dist[0] << "  # colour lens, plumb_bob\nk2: " << cam.dist[1]
      << "\np1: " << cam.dist[2] << "\np2: " << cam.dist[3] << "\nk3: " << cam.dist[4] << "\n";
  o << "width: " << cam.K.width << "  # [px]\nheight: "
    << cam.K.height << "\ndepth_scale: " << cam.depth_scale
    << "  # depth PNG value per metre\nrate_hz: " << cam.rate_hz
    << "  # [Hz]\nT_B_C: [";  // body <- camera, row-major
  const Mat4 T = cam.T_B_C.matrix();
  for (int i = 0; i < 16; ++i) o << T(i / 4, i % 4) << (i < 15 ? ", " : "");
  o << "]  # body <- camera, row-major 4x4\n";
  return writeTextFile(path, o.str());
}

Expected<std::vector<TumImageRow>> readTumImageList(const std::string& path) {
  std::vector<TumImageRow> rows;
  Status s = forEachDataLine(path, "image list", [&](const std::string& t, const std::string& where) -> Status {
    std::istringstream ss(t);
    std::string stamp, file, extra;
    ss >> stamp >> file;
    TumImageRow row;
    if (!parseDouble(stamp, &row.t) || row.t < 0) return Error{where + ": bad timestamp '" + stamp + "'"};
    if (file.empty() || (ss >> extra)) return Error{where + ": expected 'timestamp filename'"};
    row.filename = file;
    if (!rows.empty() && row.t <= rows.back().t) return Error{where + ": timestamps must increase"};
    rows.push_back(std::move(row));
    return Status::Ok();
  });
  if (!s) return Error{s.error()};
  return rows;
}

std::vector<std::pair<std::size_t, std::size_t>> associateStamps(const std::vector<double>& a,
                                                                 const std::vector<double>& b,
                                                                 double max_dt) {
  std::vector<std::tuple<double, std::size_t, std::size_t>> cand;
  for (std::size_t i = 0; i < a.size(); ++i) {
    auto it = std::lower_bound(b.begin(), b.end(), a[i] - max_dt);
    for (; it != b.end() && *it <= a[i] + max_dt; ++it)
      cand.emplace_back(std::abs(*it - a[i]), i, static_cast<std::size_t>(it - b.begin()));
  }
  std::sort(cand.begin(), cand.end());
  std::vector<char> used_a(a.size(), 0), used_b(b.size(), 0);
  std::vector<std::pair<std::size_t, std::size_t>> out;
  for (const auto& [dt, i, j] : cand) {
    if (used_a[i] || used_b[j]) continue;
    used_a[i] = used_b[j] = 1;
    out.emplace_back(i, j);
  }
  std::sort(out.begin(), out.end());
  return out;
}

Expected<TumDataset> TumDataset::open(const std::string& dir, const TumOptions& opt) {
  if (!(opt.max_dt > 0)) return Error{"TUM reader: association tolerance must be positive"};
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return Error{"TUM dataset folder '" + dir + "' does not exist"};
  TumDataset ds;
  ds.root_ = dir;
  const fs::path root(dir);

  const fs::path yaml = root / "camera.yaml";
  if (fs::exists(yaml, ec)) {
    auto cam = readTumCameraYaml(yaml.string());
    if (!cam) return Error{cam.error()};
    ds.camera_ = *cam;
  } else {
    ds.camera_ = iclNuimDefaultCamera();
    ds.default_camera_ = true;
    ds.warnings_.push_back("no camera.yaml in '" + dir +
                           "': using ICL-NUIM default intrinsics (fx 481.20, fy 480.00, "
                           "cx 319.5, cy 239.5, 640x480, depth scale 5000)");
  }
  if (opt.depth_scale > 0) ds.camera_.depth_scale = opt.depth_scale;

  const bool tum_lists = fs::exists(root / "rgb.txt", ec) && fs::exists(root / "depth.txt", ec);
  if (!tum_lists && fs::exists(root / "associations.txt", ec)) return openIclNuim(std::move(ds));
  auto rgb = readTumImageList((root / "rgb.txt").string());
  if (!rgb) return Error{rgb.error()};
  auto depth = readTumImageList((root / "depth.txt").string());
  if (!depth) return Error{depth.error()};

  auto existing = [&](const std::vector<TumImageRow>& rows, int* missing) {
    std::vector<TumImageRow> keep;
    for (const auto& r : rows) {
      if (fs::is_regular_file(root / r.filename, ec))
        keep.push_back(r);
      else
        ++*missing;
    }
    return keep;
  };
  const auto rgb_ok = existing(*rgb, &ds.skipped_.rgb_missing_image);
  const auto depth_ok = existing(*depth, &ds.skipped_.depth_missing_image);
  std::vector<double> ta, tb;
  for (const auto& r : rgb_ok) ta.push_back(r.t);
  for (const auto& r : depth_ok) tb.push_back(r.t);
  const auto assoc = associateStamps(ta, tb, opt.max_dt);
  for (const auto& [i, j] : assoc)
    ds.pairs_.push_back({ta[i], tb[j], (root / rgb_ok[i].filename).string(),
                         (root / depth_ok[j].filename).string()});
  ds.skipped_.rgb_unmatched = static_cast<int>(ta.size() - assoc.size());
  ds.skipped_.depth_unmatched = static_cast<int>(tb.size() - assoc.size());
  if (ds.pairs_.empty())
    return Error{"TUM folder '" + dir + "': no rgb/depth pair within " +
                 std::to_string(opt.max_dt) + " s"};

  const fs::path gt = root / "groundtruth.txt";
  if (fs::exists(gt, ec)) {
    auto traj = readTumTrajectory(gt.string());
    if (!traj) return Error{traj.error()};
    ds.groundtruth_ = std::move(*traj);
  }
  return ds;
}

Expected<TumDataset> TumDataset::openIclNuim(TumDataset ds) {
  std::error_code ec;
  const fs::path root(ds.root_);
  ds.icl_layout_ = true;
  const std::string list = (root / "associations.txt").string();
  auto rows = readAssociations(list);
  if (!rows) return Error{rows.error()};
  std::vector<double> stamps;
  for (const auto& r : *rows) stamps.push_back(r.t_rgb);
  const bool indices = frameIndexStamps(stamps);
  const double rate = ds.camera_.rate_hz > 0 ? ds.camera_.rate_hz : 30.0;
  const double scale = indices ? 1.0 / rate : 1.0;
  if (indices)
    ds.warnings_.push_back("ICL-NUIM layout: stamps in '" + list + "' are frame indices, read as index / " +
                           std::to_string(static_cast<int>(rate)) + " Hz");
  for (const auto& r : *rows) {
    const bool has_rgb = fs::is_regular_file(root / r.rgb, ec);
    const bool has_depth = fs::is_regular_file(root / r.depth, ec);
    if (!has_rgb) ++ds.skipped_.rgb_missing_image;
    if (!has_depth) ++ds.skipped_.depth_missing_image;
    if (has_rgb && has_depth)
      ds.pairs_.push_back({r.t_rgb * scale, r.t_depth * scale, (root / r.rgb).string(),
                           (root / r.depth).string()});
  }
  if (ds.pairs_.empty()) return Error{"ICL-NUIM folder '" + ds.root_ + "': no row of '" + list +
                                      "' has both its images"};
  const std::string gt = findFreiburgGroundTruth(root);
  if (!gt.empty()) {
    auto traj = readIclNuimGroundTruth(gt, rate);
    if (!traj) return Error{traj.error()};
    ds.groundtruth_ = std::move(*traj);
    ds.warnings_.push_back("ICL-NUIM ground truth '" + gt +
                           "': y axis mirrored from the published fy < 0 convention to the images' fy > 0");
  }
  return ds;
}

Expected<RgbdFrame> TumDataset::load(std::size_t i) const {
  if (i >= pairs_.size())
    return Error{"frame " + std::to_string(i) + " out of range (" + std::to_string(size()) +
                 " pairs in '" + root_ + "')"};
  const Pair& p = pairs_[i];
  RgbdFrame f;
  f.t = p.t_rgb;
  f.depth_t = p.t_depth;
  f.stamp_ns = std::llround(p.t_rgb * 1e9);
  f.rgb = cv::imread(p.rgb_path, cv::IMREAD_COLOR);
  if (f.rgb.empty()) return Error{"image '" + p.rgb_path + "' cannot be read"};
  if (f.rgb.cols != camera_.K.width || f.rgb.rows != camera_.K.height)
    return Error{"image '" + p.rgb_path + "' is " + std::to_string(f.rgb.cols) + "x" +
                 std::to_string(f.rgb.rows) + ", camera says " + std::to_string(camera_.K.width) +
                 "x" + std::to_string(camera_.K.height)};
  cv::cvtColor(f.rgb, f.gray, cv::COLOR_BGR2GRAY);
  const cv::Mat raw = cv::imread(p.depth_path, cv::IMREAD_ANYDEPTH);
  if (raw.empty()) return Error{"depth image '" + p.depth_path + "' cannot be read"};
  if (raw.type() != CV_16UC1)
    return Error{"depth image '" + p.depth_path + "' is not a 16-bit single-channel PNG"};
  if (raw.size() != f.rgb.size())
    return Error{"depth image '" + p.depth_path + "' size differs from its rgb image"};
  raw.convertTo(f.depth_m, CV_32F, 1.0 / camera_.depth_scale);
  return f;
}

}  // namespace hermes
