// The map back to a robot (DESIGN "Maps that last and flow back"): the server's
// downlink sends each placed robot a part of the global map around it, in
// packets of keyframes and landmarks that other trajectories (other robots, a
// prior map, the robot's own earlier sessions) mapped. Poses and positions are
// in the receiving robot's odometry frame O of the session the packet names,
// and the packet carries world <- O, so the robot holds them in the world frame
// and can place a later session of its own there (agent/borrowed_map.h).
// Packets are numbered per robot from 1 within the server's downlink epoch (a
// new one at every server start) and acknowledged by (epoch, number): the
// server resends an unacknowledged packet as it was, the robot takes each once.
//
// Binary frame: "HMDN", version 1, the receiving robot's uuid, epoch, session, seq,
// T_W_O (7 doubles), the keyframes (origin key as varints, stamp, T_O_C, the
// indices of the packet's landmarks it sees, delta-coded), the landmarks
// (origin key, p_O as three floats, descriptor), CRC-32 of everything before.
// The decoder refuses any other magic or version, a bad CRC, counts the bytes
// cannot hold, and a packet that fails validate(), naming what and where.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "hermes/core/geometry.h"
#include "hermes/core/map_types.h"
#include "hermes/core/status.h"

namespace hermes {

/// A keyframe the robot borrows: where the server holds it, and its pose.
struct BorrowedKeyframe {
  KeyframeKey origin;                   ///< (robot id, session, keyframe id) on the server
  double stamp = 0;                     ///< [s] of the robot that mapped it
  SE3 T_O_C;                            ///< camera in the receiver's odometry frame
  std::vector<std::uint32_t> landmarks; ///< indices into MapDownPacket::landmarks, ascending
};

/// A landmark the robot borrows.
struct BorrowedLandmark {
  KeyframeKey origin;   ///< (robot id, session, landmark id) on the server
  Vec3 p_O = Vec3::Zero();  ///< [m] in the receiver's odometry frame
  Descriptor descriptor{};
};

struct MapDownPacket {
  Uuid agent{};                ///< the receiving robot
  std::uint64_t epoch = 0;     ///< the server start that numbered it
  std::uint32_t session = 0;   ///< its session whose odometry frame O the poses are in
  std::uint64_t seq = 0;       ///< per robot, from 1
  SE3 T_W_O;                   ///< world <- O when the packet was planned
  std::vector<BorrowedKeyframe> keyframes;
  std::vector<BorrowedLandmark> landmarks;

  /// seq > 0, finite poses and positions, landmark indices in range and
  /// ascending, no origin key twice; the message names the first problem.
  Status validate() const;
};

/// The receiver's acknowledgement of packet `seq` (it holds what it carried).
struct MapDownAck {
  Uuid agent{};
  std::uint64_t epoch = 0;
  std::uint64_t seq = 0;
};

constexpr std::uint8_t kMapDownVersion = 1;

/// Errors: a packet that fails validate().
Expected<std::vector<std::uint8_t>> encodeMapDown(const MapDownPacket& packet);
/// `origin` names the source in error messages (topic, file).
Expected<MapDownPacket> decodeMapDown(const std::uint8_t* data, std::size_t size,
                                      const std::string& origin = "map_down");

/// Ack frame: "HMDA", the uuid, epoch, seq, CRC-32 (40 bytes).
std::vector<std::uint8_t> encodeMapDownAck(const MapDownAck& ack);
Expected<MapDownAck> decodeMapDownAck(const std::uint8_t* data, std::size_t size,
                                      const std::string& origin = "map_down_ack");

}  // namespace hermes
