#include "hermes/core/trajectory.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>

namespace hermes {

Expected<Trajectory> readTumTrajectory(const std::string& path) {
  std::ifstream in(path);
  if (!in) return Error{"trajectory file '" + path + "' cannot be opened"};
  Trajectory traj;
  std::string line;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    const auto first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    std::replace(line.begin(), line.end(), ',', ' ');
    std::istringstream ss(line);
    double t, x, y, z, qx, qy, qz, qw;
    if (!(ss >> t >> x >> y >> z >> qx >> qy >> qz >> qw))
      return Error{path + ":" + std::to_string(lineno) +
                   ": expected 8 numbers 'timestamp tx ty tz qx qy qz qw'"};
    const Quat q(qw, qx, qy, qz);
    if (!std::isfinite(q.norm()) || q.norm() < 1e-6)
      return Error{path + ":" + std::to_string(lineno) + ": quaternion is zero or not finite"};
    if (!traj.empty() && t <= traj.back().t)
      return Error{path + ":" + std::to_string(lineno) + ": timestamps must increase"};
    traj.push_back({t, SE3(q, Vec3(x, y, z))});
  }
  if (traj.empty()) return Error{"trajectory file '" + path + "' holds no poses"};
  return traj;
}

Status writeTumTrajectory(const std::string& path, const Trajectory& traj) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (!f) return Error{"cannot write trajectory file '" + path + "'"};
  std::fprintf(f, "# timestamp tx ty tz qx qy qz qw\n");
  for (const auto& p : traj) {
    const Quat& q = p.T_W_B.quat();
    const Vec3& t = p.T_W_B.translation();
    std::fprintf(f, "%.9f %.9f %.9f %.9f %.9f %.9f %.9f %.9f\n", p.t, t.x(), t.y(), t.z(), q.x(),
                 q.y(), q.z(), q.w());
  }
  if (std::fclose(f) != 0) return Error{"error while writing trajectory file '" + path + "'"};
  return Status::Ok();
}

bool interpolatePose(const Trajectory& traj, double t, SE3* out) {
  if (traj.empty() || t < traj.front().t || t > traj.back().t) return false;
  auto it = std::lower_bound(traj.begin(), traj.end(), t,
                             [](const StampedPose& p, double v) { return p.t < v; });
  if (it->t == t || it == traj.begin()) {
    *out = it->T_W_B;
    return true;
  }
  const StampedPose& b = *it;
  const StampedPose& a = *(it - 1);
  const double s = (t - a.t) / (b.t - a.t);
  *out = SE3(a.T_W_B.quat().slerp(s, b.T_W_B.quat()),
             (1 - s) * a.T_W_B.translation() + s * b.T_W_B.translation());
  return true;
}

Trajectory transformTrajectory(const Trajectory& traj, const SE3& T_B_X) {
  Trajectory out;
  out.reserve(traj.size());
  for (const auto& p : traj) out.push_back({p.t, p.T_W_B * T_B_X});
  return out;
}

}  // namespace hermes
