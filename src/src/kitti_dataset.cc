#include "hermes/core/kitti_dataset.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <opencv2/imgcodecs.hpp>

#include "dataset_text.h"
#include "hermes/core/euroc_dataset.h"

namespace fs = std::filesystem;
using namespace hermes::dataset_text;  // NOLINT: private helpers

namespace hermes {
namespace {

constexpr double kNominalRateHz = 10.0;  // KITTI's cameras

/// Splits a line into numbers; false if any field is not a number.
bool numbers(const std::string& text, std::vector<double>* out) {
  std::istringstream ss(text);
  std::string field;
  out->clear();
  while (ss >> field) {
    double v = 0;
    if (!parseDouble(field, &v) || !std::isfinite(v)) return false;
    out->push_back(v);
  }
  return true;
}

}  // namespace

Expected<KittiCalibration> readKittiCalibration(const std::string& path) {
  std::ifstream in(path);
  if (!in) return Error{"KITTI calibration '" + path + "' cannot be opened"};
  std::vector<double> p0, p1;
  std::string line;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    const std::string t = trim(line);
    const bool is0 = t.rfind("P0:", 0) == 0, is1 = t.rfind("P1:", 0) == 0;
    if (!is0 && !is1) continue;
    std::vector<double> v;
    if (!numbers(t.substr(3), &v) || v.size() != 12)
      return Error{path + ":" + std::to_string(lineno) + ": expected " + t.substr(0, 3) +
                   " followed by 12 numbers (a 3x4 projection matrix)"};
    (is0 ? p0 : p1) = v;
  }
  if (p0.empty() || p1.empty())
    return Error{path + ": needs the lines 'P0:' and 'P1:' (left and right projection matrices)"};
  KittiCalibration c;
  c.K.fx = p0[0];
  c.K.cx = p0[2];
  c.K.fy = p0[5];
  c.K.cy = p0[6];
  if (!(c.K.fx > 0 && c.K.fy > 0)) return Error{path + ": P0 must have positive fx and fy"};
  if (std::abs(p1[0] - p0[0]) > 1e-6 * p0[0] || std::abs(p1[6] - p0[6]) > 1e-6 * p0[5])
    return Error{path + ": P0 and P1 must share fx and cy (a rectified pair)"};
  c.baseline = -p1[3] / p1[0];
  if (!(c.baseline > 0)) return Error{path + ": P1[0,3] must be negative (right camera to the right)"};
  return c;
}

Expected<Trajectory> readKittiPoses(const std::string& path, const std::vector<double>& stamps) {
  std::ifstream in(path);
  if (!in) return Error{"KITTI poses '" + path + "' cannot be opened"};
  Trajectory traj;
  std::string line;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    if (trim(line).empty()) continue;
    const std::string where = path + ":" + std::to_string(lineno);
    std::vector<double> v;
    if (!numbers(line, &v) || v.size() != 12) return Error{where + ": expected 12 numbers (3x4 pose)"};
    if (traj.size() >= stamps.size()) break;  // poses beyond the frames we have
    Mat3 R;
    Vec3 t;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) R(r, c) = v[static_cast<std::size_t>(r * 4 + c)];
      t(r) = v[static_cast<std::size_t>(r * 4 + 3)];
    }
    if ((R.transpose() * R - Mat3::Identity()).norm() > 1e-3 || R.determinant() < 0)
      return Error{where + ": the rotation is not orthonormal"};
    traj.push_back({stamps[traj.size()], SE3(R, t)});
  }
  return traj;
}

bool looksLikeKittiSequence(const std::string& dir) {
  std::error_code ec;
  const fs::path d(dir);
  return fs::is_directory(d / "image_0", ec) && fs::is_directory(d / "image_1", ec) &&
         fs::is_regular_file(d / "calib.txt", ec);
}

Expected<KittiDataset> KittiDataset::open(const std::string& dir) {
  if (!looksLikeKittiSequence(dir))
    return Error{"'" + dir + "' is not a KITTI odometry sequence (image_0/, image_1/, calib.txt)"};
  KittiDataset ds;
  ds.root_ = dir;
  const fs::path root(dir);
  auto calib = readKittiCalibration((root / "calib.txt").string());
  if (!calib) return Error{calib.error()};
  ds.calib_ = *calib;

  std::vector<std::string> names;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(root / "image_0", ec))
    if (e.path().extension() == ".png") names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  if (names.empty()) return Error{"KITTI sequence '" + dir + "': image_0/ holds no PNG"};

  // Frame index = file stem (000000.png is frame 0); stamps from times.txt.
  std::vector<double> times;
  const fs::path times_path = root / "times.txt";
  if (fs::exists(times_path, ec)) {
    std::ifstream in(times_path);
    std::string line;
    int lineno = 0;
    while (std::getline(in, line)) {
      ++lineno;
      const std::string t = trim(line);
      if (t.empty()) continue;
      double v = 0;
      if (!parseDouble(t, &v) || !std::isfinite(v) || (!times.empty() && v <= times.back()))
        return Error{times_path.string() + ":" + std::to_string(lineno) +
                     ": expected one increasing stamp in seconds"};
      times.push_back(v);
    }
  } else {
    ds.warnings_.push_back("no times.txt in '" + dir + "': frames stamped at the nominal 10 Hz");
  }
  int missing_right = 0, beyond_times = 0;
  for (const auto& name : names) {
    std::int64_t index = 0;
    if (!parseInt64(fs::path(name).stem().string(), &index) || index < 0) continue;
    if (!fs::is_regular_file(root / "image_1" / name, ec)) {
      ++missing_right;
      continue;
    }
    double t = static_cast<double>(index) / kNominalRateHz;
    if (!times.empty()) {
      if (static_cast<std::size_t>(index) >= times.size()) {
        ++beyond_times;
        continue;
      }
      t = times[static_cast<std::size_t>(index)];
    }
    ds.pairs_.push_back({t, (root / "image_0" / name).string(), (root / "image_1" / name).string()});
  }
  if (missing_right > 0)
    ds.warnings_.push_back(std::to_string(missing_right) + " left images without a right one skipped");
  if (beyond_times > 0)
    ds.warnings_.push_back(std::to_string(beyond_times) + " images beyond times.txt's rows skipped");
  if (ds.pairs_.empty()) return Error{"KITTI sequence '" + dir + "': no stereo pair to read"};

  // Image size from the first left image's header.
  const cv::Mat first = cv::imread(ds.pairs_.front().left_path, cv::IMREAD_GRAYSCALE);
  if (first.empty()) return Error{"image '" + ds.pairs_.front().left_path + "' cannot be read"};
  ds.calib_.K.width = first.cols;
  ds.calib_.K.height = first.rows;

  // Ground truth: <root>/../../poses/NN.txt, NN = this folder's name.
  const fs::path seq = fs::absolute(root, ec).lexically_normal();
  const std::string nn = (seq.filename().empty() ? seq.parent_path() : seq).filename().string();
  const fs::path poses = seq.parent_path().parent_path() / "poses" / (nn + ".txt");
  if (fs::exists(poses, ec)) {
    std::vector<double> stamps;  // one per frame index, in file order
    const std::size_t n = times.empty() ? names.size() : times.size();
    for (std::size_t i = 0; i < n; ++i)
      stamps.push_back(times.empty() ? static_cast<double>(i) / kNominalRateHz : times[i]);
    auto gt = readKittiPoses(poses.string(), stamps);
    if (!gt) return Error{gt.error()};
    ds.groundtruth_ = std::move(*gt);
  }
  return ds;
}

Expected<StereoFrame> KittiDataset::load(std::size_t i) const {
  if (i >= pairs_.size())
    return Error{"frame " + std::to_string(i) + " out of range (" + std::to_string(size()) +
                 " pairs in '" + root_ + "')"};
  StereoFrame f;
  f.t = pairs_[i].t;
  f.stamp_ns = std::llround(f.t * 1e9);
  auto l = loadGrayImage(pairs_[i].left_path, calib_.K.width, calib_.K.height);
  if (!l) return Error{l.error()};
  auto r = loadGrayImage(pairs_[i].right_path, calib_.K.width, calib_.K.height);
  if (!r) return Error{r.error()};
  f.left = *l;
  f.right = *r;
  f.rectified = true;
  return f;
}

}  // namespace hermes
