#include "hermes/server/admission.h"

#include <algorithm>

namespace hermes {

Status AuthParams::read(const Config& c, const std::string& p) {
  for (auto s : {c.get(p + "enabled", &enabled), c.get(p + "key_dir", &key_dir)})
    if (!s) return s;
  return validate();
}

void AuthParams::write(ConfigWriter& w, const std::string& p) const {
  w.set(p + "enabled", enabled);
  w.set(p + "key_dir", key_dir);
}

Status AuthParams::validate() const {
  if (enabled && key_dir.empty())
    return Error{"server.auth.key_dir must name the key directory when server.auth.enabled"};
  return Status::Ok();
}

Status QueueParams::read(const Config& c, const std::string& p) {
  for (auto s : {c.get(p + "max_per_robot", &max_per_robot),
                 c.get(p + "max_mbytes_per_robot", &max_mbytes_per_robot)})
    if (!s) return s;
  return validate();
}

void QueueParams::write(ConfigWriter& w, const std::string& p) const {
  w.set(p + "max_per_robot", max_per_robot);
  w.set(p + "max_mbytes_per_robot", max_mbytes_per_robot);
}

Status QueueParams::validate() const {
  if (max_per_robot < 1)
    return Error{"server.queue.max_per_robot must be >= 1, got " + std::to_string(max_per_robot)};
  if (!(max_mbytes_per_robot > 0))
    return Error{"server.queue.max_mbytes_per_robot must be > 0, got " +
                 std::to_string(max_mbytes_per_robot)};
  return Status::Ok();
}

std::string RobotQuotas::admit(RobotId robot, std::size_t bytes) {
  HeldLoad& l = loads_[robot];
  if (l.submaps == 0) return {};  // one submap always fits: none is refused forever
  const double cap_bytes = params_.max_mbytes_per_robot * 1e6;
  std::string why;
  if (l.submaps >= static_cast<std::size_t>(params_.max_per_robot))
    why = std::to_string(l.submaps) + " submaps held (server.queue.max_per_robot " +
          std::to_string(params_.max_per_robot) + ")";
  else if (static_cast<double>(l.bytes + bytes) > cap_bytes)
    why = std::to_string(l.bytes) + " bytes held + " + std::to_string(bytes) +
          " would exceed server.queue.max_mbytes_per_robot (" +
          std::to_string(static_cast<long long>(cap_bytes)) + " bytes)";
  if (why.empty()) return {};
  ++l.refused;
  return why;
}

void RobotQuotas::hold(RobotId robot, std::size_t bytes) {
  HeldLoad& l = loads_[robot];
  ++l.submaps;
  l.bytes += bytes;
  l.peak_submaps = std::max(l.peak_submaps, l.submaps);
  l.peak_bytes = std::max(l.peak_bytes, l.bytes);
}

void RobotQuotas::release(RobotId robot, std::size_t bytes) {
  auto it = loads_.find(robot);
  HERMES_CHECK(it != loads_.end() && it->second.submaps > 0 && it->second.bytes >= bytes,
               "quota release without a matching hold");
  --it->second.submaps;
  it->second.bytes -= bytes;
}

const HeldLoad* RobotQuotas::load(RobotId robot) const {
  auto it = loads_.find(robot);
  return it == loads_.end() ? nullptr : &it->second;
}

}  // namespace hermes
