#include "hermes/core/eval_io.h"

#include "hermes/core/dataset.h"
#include "hermes/core/euroc_dataset.h"
#include "hermes/core/tum_dataset.h"

#include <sys/stat.h>

#include <Eigen/SVD>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <sstream>

#include <yaml-cpp/yaml.h>

namespace hermes {
namespace eval {

namespace {

bool isDirectory(const std::string& p) {
  struct stat st {};
  return ::stat(p.c_str(), &st) == 0 && S_ISDIR(st.st_mode);
}
bool isFile(const std::string& p) {
  struct stat st {};
  return ::stat(p.c_str(), &st) == 0 && S_ISREG(st.st_mode);
}

}  // namespace

Expected<Trajectory> readEurocGroundTruthCsv(const std::string& path) {
  return readEurocGroundTruth(path);  // the dataset reader; one parser for the format
}

Expected<std::string> resolveTrajectoryPath(const std::string& path) {
  if (isFile(path)) return path;
  if (!isDirectory(path)) return Error{"trajectory '" + path + "' does not exist"};
  for (const char* rel : {"/mav0/state_groundtruth_estimate0/data.csv",
                          "/state_groundtruth_estimate0/data.csv", "/data.csv"}) {
    const std::string p = path + rel;
    if (isFile(p)) return p;
  }
  return Error{"folder '" + path +
               "' holds no EuRoC ground truth (mav0/state_groundtruth_estimate0/data.csv)"};
}

Expected<TrajectoryFormat> detectTrajectoryFormat(const std::string& file) {
  std::ifstream in(file);
  if (!in) return Error{"trajectory file '" + file + "' cannot be opened"};
  std::string line;
  while (std::getline(in, line)) {
    const auto first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos) continue;
    if (line[first] == '#') {
      if (line.find("p_RS_R_x") != std::string::npos) return TrajectoryFormat::kEurocCsv;
      continue;
    }
    std::istringstream fields(line);
    int count = 0;
    for (std::string f; fields >> f;) ++count;
    if (count == 12)
      return Error{"'" + file + "' looks like a KITTI poses file (12 numbers a row, no stamps): "
                   "give the sequence folder (sequences/NN) instead"};
    std::string token = line.substr(first, line.find_first_of(" \t,", first) - first);
    const bool integer = !token.empty() && std::all_of(token.begin(), token.end(), ::isdigit);
    if (integer && token.size() >= 13) return TrajectoryFormat::kEurocCsv;  // >= 1e12 ns
    return TrajectoryFormat::kTum;
  }
  return Error{"trajectory file '" + file + "' holds no poses"};
}

Expected<SE3> readEurocSensorExtrinsic(const std::string& path) {
  std::ifstream in(path);
  if (!in) return Error{"sensor file '" + path + "' cannot be opened"};
  std::string text, line;
  while (std::getline(in, line))
    if (line.rfind('%', 0) != 0) text += line + "\n";  // drop OpenCV's %YAML:1.0
  std::vector<double> d;
  try {
    const YAML::Node root = YAML::Load(text);
    const YAML::Node data = root["T_BS"]["data"];
    if (!data || !data.IsSequence())
      return Error{"sensor file '" + path + "' has no list 'T_BS.data'"};
    d = data.as<std::vector<double>>();
  } catch (const YAML::Exception& e) {
    return Error{"sensor file '" + path + "': " + e.what()};
  }
  if (d.size() != 16)
    return Error{"sensor file '" + path + "': T_BS.data must hold 16 numbers, got " +
                 std::to_string(d.size())};
  Mat4 T;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) T(r, c) = d[size_t(4 * r + c)];
  const Mat3 R = T.topLeftCorner<3, 3>();
  if (!T.allFinite() || (R.transpose() * R - Mat3::Identity()).norm() > 1e-3 ||
      R.determinant() < 0)
    return Error{"sensor file '" + path + "': T_BS is not a rigid transform"};
  // Re-orthonormalise (the file holds ~10 digits).
  Eigen::JacobiSVD<Mat3> svd(R, Eigen::ComputeFullU | Eigen::ComputeFullV);
  return SE3(Mat3(svd.matrixU() * svd.matrixV().transpose()), Vec3(T.topRightCorner<3, 1>()));
}

Expected<Trajectory> readTrajectoryForEval(const std::string& path) {
  if (isDirectory(path) && !resolveTrajectoryPath(path).ok()) {
    // Any other dataset folder: the ground truth its reader finds, in its conventions.
    auto ds = probeDataset(path);
    if (!ds) return Error{"folder '" + path + "': " + ds.error()};
    if (ds->groundtruth.empty()) return Error{"dataset '" + path + "' has no ground truth"};
    return ds->groundtruth;
  }
  Expected<std::string> file = resolveTrajectoryPath(path);
  if (!file) return Error{file.error()};
  if (isIclNuimGroundTruthName(*file)) return readIclNuimGroundTruth(*file);
  Expected<TrajectoryFormat> fmt = detectTrajectoryFormat(*file);
  if (!fmt) return Error{fmt.error()};
  return *fmt == TrajectoryFormat::kEurocCsv ? readEurocGroundTruthCsv(*file)
                                             : readTumTrajectory(*file);
}

}  // namespace eval
}  // namespace hermes
