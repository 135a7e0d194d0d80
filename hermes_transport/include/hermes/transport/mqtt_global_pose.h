// The robot's place in the global map over MQTT (issue 19 item 4, as
// hermes_msgs/GlobalPose is over ROS): after merges the server publishes each
// anchored robot's world <- odometry (GlobalPoseUpdate, global_pose.h) on
//   hermes/<agent>/global_pose   server -> agent, QoS 0: repeated after every
//                                merge, and a robot keeps only the newest of its
//                                current session, so nothing is worth queueing.
//
// GlobalPoseMessage (100 bytes; integers and doubles little-endian)
//   offset size  field
//        0    4  magic "HGPS"
//        4    1  version (1)
//        5    3  reserved, 0
//        8   16  agent uuid (the robot's; it checks it is its own)
//       24    4  session the keyframe belongs to
//       28    8  keyframes merged of that session
//       36    8  keyframe stamp [s] (f64)
//       44   24  T_W_O translation x, y, z [m] (f64)
//       68   32  T_W_O rotation quaternion x, y, z, w (f64, unit)
//
// Decoding errors start with "mqtt global pose: " and name the field and its
// offset; a decoded update passed GlobalPoseUpdate::validate().
#pragma once

#include <cstdint>
#include <vector>

#include "hermes/core/global_pose.h"
#include "hermes/core/map_types.h"
#include "hermes/core/status.h"

namespace hermes::transport {

constexpr std::size_t kGlobalPoseMessageBytes = 100;

struct GlobalPoseMessage {
  Uuid agent{};
  GlobalPoseUpdate update;
};

/// Errors: an update that fails GlobalPoseUpdate::validate().
Expected<std::vector<std::uint8_t>> encodeGlobalPose(const GlobalPoseMessage& msg);
Expected<GlobalPoseMessage> decodeGlobalPose(const std::uint8_t* data, std::size_t size);

}  // namespace hermes::transport
