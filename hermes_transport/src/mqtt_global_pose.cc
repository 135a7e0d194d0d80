#include "hermes/transport/mqtt_global_pose.h"

#include <cmath>
#include <cstring>

#include "le_bytes.h"

namespace hermes::transport {
namespace {

constexpr std::uint8_t kGlobalPoseVersion = 1;
constexpr char kMagic[] = "HGPS";

void putDouble(std::vector<std::uint8_t>* out, double d) {
  std::uint64_t v = 0;
  std::memcpy(&v, &d, sizeof v);
  le::put(out, v, 8);
}

double getDouble(const std::uint8_t* p) {
  const std::uint64_t v = le::get(p, 8);
  double d = 0;
  std::memcpy(&d, &v, sizeof d);
  return d;
}

}  // namespace

Expected<std::vector<std::uint8_t>> encodeGlobalPose(const GlobalPoseMessage& msg) {
  if (Status s = msg.update.validate(); !s) return Error{"mqtt global pose: " + s.error()};
  std::vector<std::uint8_t> out;
  out.reserve(kGlobalPoseMessageBytes);
  out.insert(out.end(), {'H', 'G', 'P', 'S', kGlobalPoseVersion, 0, 0, 0});
  out.insert(out.end(), msg.agent.begin(), msg.agent.end());
  le::put(&out, msg.update.session, 4);
  le::put(&out, msg.update.keyframes, 8);
  putDouble(&out, msg.update.keyframe_stamp);
  const Vec3& t = msg.update.T_W_O.translation();
  const Quat& q = msg.update.T_W_O.quat();
  for (double v : {t.x(), t.y(), t.z(), q.x(), q.y(), q.z(), q.w()}) putDouble(&out, v);
  return out;
}

Expected<GlobalPoseMessage> decodeGlobalPose(const std::uint8_t* data, std::size_t size) {
  const std::string prefix = "mqtt global pose: ";
  if (!data && size > 0) return Error{prefix + "no data"};
  if (size != kGlobalPoseMessageBytes)
    return Error{prefix + "payload of " + std::to_string(size) + " bytes, expected " +
                 std::to_string(kGlobalPoseMessageBytes)};
  if (std::memcmp(data, kMagic, 4) != 0) return Error{prefix + "bad magic at offset 0 (expected \"HGPS\")"};
  if (data[4] != kGlobalPoseVersion)
    return Error{prefix + "unsupported version " + std::to_string(data[4]) +
                 " at offset 4 (this build reads " + std::to_string(kGlobalPoseVersion) + ")"};
  if (data[5] != 0 || data[6] != 0 || data[7] != 0)
    return Error{prefix + "reserved bytes at offsets 5..7 are not 0"};
  GlobalPoseMessage m;
  std::memcpy(m.agent.data(), data + 8, m.agent.size());
  m.update.session = static_cast<std::uint32_t>(le::get(data + 24, 4));
  m.update.keyframes = le::get(data + 28, 8);
  m.update.keyframe_stamp = getDouble(data + 36);
  if (!std::isfinite(m.update.keyframe_stamp)) return Error{prefix + "keyframe stamp at offset 36 is not finite"};
  const Vec3 t(getDouble(data + 44), getDouble(data + 52), getDouble(data + 60));
  const Quat q(getDouble(data + 92), getDouble(data + 68), getDouble(data + 76), getDouble(data + 84));
  if (!t.allFinite()) return Error{prefix + "translation at offset 44 is not finite"};
  if (!q.coeffs().allFinite() || std::abs(q.norm() - 1.0) > 1e-6)
    return Error{prefix + "rotation at offset 68 is not a unit quaternion"};
  m.update.T_W_O = SE3(q, t);
  if (Status s = m.update.validate(); !s) return Error{prefix + s.error()};
  return m;
}

}  // namespace hermes::transport
