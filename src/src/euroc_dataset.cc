#include "hermes/core/euroc_dataset.h"

#include <yaml-cpp/yaml.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <sstream>
#include <unordered_map>

#include <opencv2/imgcodecs.hpp>

#include "dataset_text.h"

namespace fs = std::filesystem;
using namespace hermes::dataset_text;  // NOLINT: private helpers

namespace hermes {
namespace {

Expected<std::vector<double>> numberList(const YAML::Node& n, std::size_t expected,
                                         const std::string& key, const std::string& path) {
  if (!n || !n.IsSequence() || n.size() != expected)
    return Error{path + ": '" + key + "' must be a list of " + std::to_string(expected) +
                 " numbers"};
  std::vector<double> v;
  for (const auto& e : n) {
    try {
      v.push_back(e.as<double>());
    } catch (const YAML::Exception&) {
      return Error{path + ":" + std::to_string(e.Mark().line + 1) + ": '" + key +
                   "' holds a non-number"};
    }
    if (!std::isfinite(v.back())) return Error{path + ": '" + key + "' holds a non-finite value"};
  }
  return v;
}

Expected<std::string> scalarString(const YAML::Node& root, const std::string& key,
                                   const std::string& path) {
  const YAML::Node n = root[key];
  if (!n || !n.IsScalar()) return Error{path + ": missing key '" + key + "'"};
  return n.as<std::string>();
}

}  // namespace

Expected<PinholeRadtan> readEurocCameraYaml(const std::string& path) {
  auto text = readTextFile(path);
  if (!text) return Error{text.error()};
  // OpenCV-style "%YAML:1.0" is not a valid YAML 1.2 directive; comment it out
  // (keeping line numbers) before handing the text to yaml-cpp.
  std::string& s = *text;
  if (s.rfind("%YAML", 0) == 0) s[0] = '#';
  YAML::Node root;
  try {
    root = YAML::Load(s);
  } catch (const YAML::Exception& e) {
    return Error{path + ":" + std::to_string(e.mark.line + 1) + ": YAML error: " + e.msg};
  }
  if (!root.IsMap()) return Error{path + ": not a YAML map"};
  PinholeRadtan cam;
  try {
    auto model = scalarString(root, "camera_model", path);
    if (!model) return Error{model.error()};
    if (*model != "pinhole")
      return Error{path + ": unsupported camera_model '" + *model + "' (supported: pinhole)"};
    auto dmodel = scalarString(root, "distortion_model", path);
    if (!dmodel) return Error{dmodel.error()};
    if (*dmodel != "radial-tangential" && *dmodel != "radtan")
      return Error{path + ": unsupported distortion_model '" + *dmodel +
                   "' (supported: radial-tangential)"};

    const YAML::Node tbs = root["T_BS"];
    if (!tbs || !tbs.IsMap()) return Error{path + ": missing map 'T_BS'"};
    if (tbs["rows"] && tbs["cols"] &&
        (tbs["rows"].as<int>() != 4 || tbs["cols"].as<int>() != 4))
      return Error{path + ": 'T_BS' must be 4x4"};
    auto data = numberList(tbs["data"], 16, "T_BS.data", path);
    if (!data) return Error{data.error()};
    Mat4 T;
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) T(r, c) = (*data)[4 * r + c];
    const Mat3 R = T.topLeftCorner<3, 3>();
    const double ortho = (R.transpose() * R - Mat3::Identity()).norm();
    if (ortho > 1e-4 || R.determinant() < 0 ||
        (T.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).norm() > 1e-9)
      return Error{path + ": 'T_BS' is not a rigid transform (rotation error " +
                   std::to_string(ortho) + ")"};
    cam.T_B_C = SE3(T);

    const YAML::Node rate = root["rate_hz"];
    if (rate) cam.rate_hz = rate.as<double>();
    if (!(cam.rate_hz > 0)) return Error{path + ": 'rate_hz' must be positive"};

    auto res = numberList(root["resolution"], 2, "resolution", path);
    if (!res) return Error{res.error()};
    cam.K.width = static_cast<int>((*res)[0]);
    cam.K.height = static_cast<int>((*res)[1]);
    if (cam.K.width <= 0 || cam.K.height <= 0 || cam.K.width != (*res)[0] ||
        cam.K.height != (*res)[1])
      return Error{path + ": 'resolution' must be two positive integers"};

    auto intr = numberList(root["intrinsics"], 4, "intrinsics", path);
    if (!intr) return Error{intr.error()};
    cam.K.fx = (*intr)[0];
    cam.K.fy = (*intr)[1];
    cam.K.cx = (*intr)[2];
    cam.K.cy = (*intr)[3];
    if (!(cam.K.fx > 0 && cam.K.fy > 0))
      return Error{path + ": 'intrinsics' focal lengths must be positive"};

    auto d = numberList(root["distortion_coefficients"], 4, "distortion_coefficients", path);
    if (!d) return Error{d.error()};
    for (int i = 0; i < 4; ++i) cam.dist[i] = (*d)[i];
  } catch (const YAML::Exception& e) {
    return Error{path + ":" + std::to_string(e.mark.line + 1) + ": bad value: " + e.msg};
  }
  return cam;
}

Status writeEurocCameraYaml(const std::string& path, const PinholeRadtan& cam,
                            const std::string& comment) {
  if (cam.model != DistortionModel::kRadtan || cam.distortionCount() != 4)
    return Error{path + ": a EuRoC sensor.yaml holds radial-tangential k1 k2 p1 p2 only " +
                 "(camera has " + std::string(toString(cam.model)) + " with " +
                 std::to_string(cam.distortionCount()) + " coefficients)"};
  std::ostringstream o;
  o.precision(17);
  o << "%YAML:1.0\n# General sensor definitions.\nsensor_type: camera\ncomment: " << comment
    << "\n\n# Sensor extrinsics wrt. the body-frame.\nT_BS:\n  cols: 4\n  rows: 4\n  data: [";
  const Mat4 T = cam.T_B_C.matrix();
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) {
      o << T(r, c);
      if (r * 4 + c < 15) o << ", ";
    }
    if (r < 3) o << "\n         ";
  }
  o << "]\n\n# Camera specific definitions.\nrate_hz: " << cam.rate_hz << "\nresolution: ["
    << cam.K.width << ", " << cam.K.height << "]\ncamera_model: pinhole\nintrinsics: ["
    << cam.K.fx << ", " << cam.K.fy << ", " << cam.K.cx << ", " << cam.K.cy
    << "] #fu, fv, cu, cv\ndistortion_model: radial-tangential\ndistortion_coefficients: ["
    << cam.dist[0] << ", " << cam.dist[1] << ", " << cam.dist[2] << ", " << cam.dist[3]
    << "]\n";
  return writeTextFile(path, o.str());
}

Expected<std::vector<EurocImageRow>> readEurocImageCsv(const std::string& path) {
  std::vector<EurocImageRow> rows;
  Status s = forEachDataLine(path, "image list", [&](const std::string& t, const std::string& where) -> Status {
    const auto comma = t.find(',');
    if (comma == std::string::npos) return Error{where + ": expected 'timestamp_ns,filename'"};
    EurocImageRow row;
    if (!parseInt64(trim(t.substr(0, comma)), &row.stamp_ns) || row.stamp_ns < 0)
      return Error{where + ": bad timestamp '" + t.substr(0, comma) + "'"};
    row.filename = trim(t.substr(comma + 1));
    if (row.filename.empty() || row.filename.find(',') != std::string::npos)
      return Error{where + ": expected one file name after the timestamp"};
    if (!rows.empty() && row.stamp_ns <= rows.back().stamp_ns) return Error{where + ": timestamps must increase"};
    rows.push_back(std::move(row));
    return Status::Ok();
  });
  if (!s) return Error{s.error()};
  return rows;
}

Expected<Trajectory> readEurocGroundTruth(const std::string& path,
                                          std::vector<std::int64_t>* stamps_ns) {
  Trajectory traj;
  std::vector<std::int64_t> stamps;
  Status s = forEachDataLine(path, "ground truth", [&](const std::string& t, const std::string& where) -> Status {
    const std::vector<std::string> f = splitFields(t, ',');
    if (f.size() < 8) return Error{where + ": expected at least 8 fields 'ns,px,py,pz,qw,qx,qy,qz'"};
    std::int64_t ns = 0;
    if (!parseInt64(f[0], &ns)) return Error{where + ": bad timestamp '" + f[0] + "'"};
    double v[7];
    for (int i = 0; i < 7; ++i)
      if (!parseDouble(f[i + 1], &v[i])) return Error{where + ": bad number '" + f[i + 1] + "'"};
    const Quat q(v[3], v[4], v[5], v[6]);
    if (!(q.norm() > 1e-6)) return Error{where + ": quaternion is zero"};
    if (!stamps.empty() && ns <= stamps.back()) return Error{where + ": timestamps must increase"};
    stamps.push_back(ns);
    traj.push_back({nsToSeconds(ns), SE3(q, Vec3(v[0], v[1], v[2]))});
    return Status::Ok();
  });
  if (!s) return Error{s.error()};
  if (traj.empty()) return Error{"ground truth '" + path + "' holds no poses"};
  if (stamps_ns) *stamps_ns = std::move(stamps);
  return traj;
}

Expected<cv::Mat> loadGrayImage(const std::string& path, int width, int height) {
  cv::Mat img = cv::imread(path, cv::IMREAD_GRAYSCALE);
  if (img.empty()) return Error{"image '" + path + "' cannot be read"};
  if (img.cols != width || img.rows != height)
    return Error{"image '" + path + "' is " + std::to_string(img.cols) + "x" +
                 std::to_string(img.rows) + ", calibration says " + std::to_string(width) + "x" +
                 std::to_string(height)};
  return img;
}

Expected<EurocDataset> EurocDataset::open(const std::string& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return Error{"EuRoC dataset folder '" + dir + "' does not exist"};
  EurocDataset ds;
  if (fs::is_directory(fs::path(dir) / "mav0", ec))
    ds.mav0_ = (fs::path(dir) / "mav0").string();
  else if (fs::is_directory(fs::path(dir) / "cam0", ec))
    ds.mav0_ = dir;
  else
    return Error{"'" + dir + "' is not a EuRoC folder (no mav0/ or cam0/ inside)"};
  const fs::path m(ds.mav0_);

  auto c0 = readEurocCameraYaml((m / "cam0" / "sensor.yaml").string());
  if (!c0) return Error{c0.error()};
  auto c1 = readEurocCameraYaml((m / "cam1" / "sensor.yaml").string());
  if (!c1) return Error{c1.error()};
  ds.cam0_ = *c0;
  ds.cam1_ = *c1;

  auto r0 = readEurocImageCsv((m / "cam0" / "data.csv").string());
  if (!r0) return Error{r0.error()};
  auto r1 = readEurocImageCsv((m / "cam1" / "data.csv").string());
  if (!r1) return Error{r1.error()};

  // Keep only rows whose image exists, then match by exact stamp.
  std::unordered_map<std::int64_t, std::string> right;
  for (const auto& row : *r1) {
    const std::string p = (m / "cam1" / "data" / row.filename).string();
    if (fs::is_regular_file(p, ec))
      right.emplace(row.stamp_ns, p);
    else
      ++ds.skipped_.cam1_missing_image;
  }
  std::size_t matched_right = 0;
  for (const auto& row : *r0) {
    const std::string p = (m / "cam0" / "data" / row.filename).string();
    if (!fs::is_regular_file(p, ec)) {
      ++ds.skipped_.cam0_missing_image;
      continue;
    }
    auto it = right.find(row.stamp_ns);
    if (it == right.end()) {
      ++ds.skipped_.cam0_unpaired;
      continue;
    }
    ds.pairs_.push_back({row.stamp_ns, p, it->second});
    ++matched_right;
  }
  ds.skipped_.cam1_unpaired = static_cast<int>(right.size() - matched_right);
  if (ds.pairs_.empty()) return Error{"EuRoC folder '" + ds.mav0_ + "' holds no stereo pair"};

  const fs::path gt = m / "state_groundtruth_estimate0" / "data.csv";
  if (fs::exists(gt, ec)) {
    auto traj = readEurocGroundTruth(gt.string(), &ds.gt_stamps_ns_);
    if (!traj) return Error{traj.error()};
    ds.groundtruth_ = std::move(*traj);
  }
  return ds;
}

Expected<StereoFrame> EurocDataset::load(std::size_t i) const {
  if (i >= pairs_.size())
    return Error{"frame " + std::to_string(i) + " out of range (" + std::to_string(size()) +
                 " pairs in '" + mav0_ + "')"};
  StereoFrame f;
  f.stamp_ns = pairs_[i].stamp_ns;
  f.t = nsToSeconds(f.stamp_ns);
  auto l = loadGrayImage(pairs_[i].left_path, cam0_.K.width, cam0_.K.height);
  if (!l) return Error{l.error()};
  auto r = loadGrayImage(pairs_[i].right_path, cam1_.K.width, cam1_.K.height);
  if (!r) return Error{r.error()};
  f.left = *l;
  f.right = *r;
  return f;
}

}  // namespace hermes
