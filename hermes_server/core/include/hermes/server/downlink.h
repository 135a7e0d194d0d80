// The map back to the robots (DESIGN "Maps that last and flow back"): after
// merges, each placed robot gets a packet (core/map_down.h) of the global map
// around it that it does not hold yet - keyframes and landmarks that other
// trajectories mapped (other robots, a prior map, its own earlier sessions),
// never its current session's own.
//
// Selection. The neighbourhood is every anchored keyframe within radius_m of
// the robot's newest merged keyframe. A robot whose current session is not
// placed (it lost track and started a new map) gets the map around its newest
// placed earlier session, in that session's frame: what it saw last, its own
// keyframes there first, is what it relocalises against (agent/borrowed_map.h). Its landmarks are scored with the
// uplink's own scores (distill::computeScores: stability and the future-aware
// information gain for the robot's predicted poses, from the motion between
// its two newest keyframes), so what is sent first is what the robot is about
// to see. Keyframes go nearest first, each with its best landmarks_per_keyframe
// landmarks not sent yet, until the packet reaches what the budget allows.
//
// Budget. A token bucket per robot, refilled at bytes_per_s and burst_s deep,
// pays for every byte put on the link, resends included: over any interval a
// robot receives at most bytes_per_s * interval + the bucket. At most
// max_in_flight packets wait for an acknowledgement; a packet is planned only
// when the bucket holds min_packet_bytes (no trickle of tiny packets).
//
// Exactly once. Packets are numbered per robot from 1 within the downlink's
// epoch (a new one every server start: the robot keys what it took by both).
// An unacknowledged packet is sent again, the same bytes, resend_after_s after
// its last send; what it carries is not planned again, and once acknowledged
// never again. Robots drop what they took already, so a resend whose
// acknowledgement was lost costs bytes, never a double.
//
// Not thread-safe: plan() reads the map on the merging thread, after process().
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "hermes/core/config.h"
#include "hermes/core/map_down.h"
#include "hermes/server/global_map.h"

namespace hermes {
namespace server {

struct DownlinkParams {
  bool enabled = true;             ///< send each placed robot the map around it
  double bytes_per_s = 2000;       ///< budget per robot [B/s]
  double burst_s = 10;             ///< token bucket depth [s of budget]
  double radius_m = 6;             ///< neighbourhood of the robot's newest merged keyframe [m]
  int landmarks_per_keyframe = 60; ///< best-scored landmarks sent with a borrowed keyframe
  int min_packet_bytes = 2000;     ///< a packet is planned once the bucket holds this [B]
  int max_packet_bytes = 16000;    ///< largest packet [B]
  int max_in_flight = 2;           ///< unacknowledged packets per robot
  double resend_after_s = 4;       ///< unacknowledged packet sent again after [s]
  Status read(const Config& config, const std::string& prefix = "server.downlink.");
  void write(ConfigWriter& out, const std::string& prefix = "server.downlink.") const;
  Status validate() const;
};

/// A robot the downlink serves: its server id, uuid and current session.
struct DownlinkRecipient {
  std::uint32_t robot = 0;
  Uuid agent{};
  std::uint32_t session = 0;
};

/// Bytes and items sent to one robot.
struct DownlinkRobotStats {
  std::uint64_t bytes = 0;          ///< every byte put on the link, resends included
  std::uint64_t packets = 0, resends = 0, acked = 0;
  std::uint64_t keyframes = 0, landmarks = 0;  ///< acknowledged items
  double first_send_s = -1;         ///< [s] first packet (-1: none yet)
};

class Downlink {
 public:
  struct Outgoing {
    std::uint32_t robot = 0;
    Uuid agent{};
    std::uint64_t seq = 0;
    bool resend = false;
    std::shared_ptr<const std::vector<std::uint8_t>> bytes;
  };

  /// `epoch`: a number that differs between server starts (e.g. resumes + 1).
  Downlink(const DownlinkParams& params, std::uint64_t epoch);

  /// At `now` [s]: resends due, then a new packet for each recipient that is
  /// placed (its current session anchored) and whose budget allows. Robots
  /// not listed are not served (their in-flight packets wait).
  std::vector<Outgoing> plan(const GlobalMap& map, const std::vector<DownlinkRecipient>& recipients,
                             double now);
  /// The robot holds packet (epoch, seq). Unknown or repeated acks are ignored
  /// (false).
  bool onAck(const MapDownAck& ack, double now);
  /// A robot's link came back (e.g. reconnected): its in-flight packets may be
  /// sent again at once.
  void onReconnect(const Uuid& agent);

  std::uint64_t epoch() const { return epoch_; }
  const DownlinkParams& params() const { return params_; }
  /// Per robot id (robots served at least once).
  const std::map<std::uint32_t, DownlinkRobotStats>& stats() const { return stats_; }
  /// Packets waiting for an acknowledgement, over all robots.
  std::size_t inFlight() const;

 private:
  struct Packet {
    std::shared_ptr<const std::vector<std::uint8_t>> bytes;
    double sent_at = 0;
    std::vector<KeyframeKey> keyframes, landmarks;
  };
  struct Robot {
    std::uint32_t id = 0;
    double tokens = 0, refilled_at = -1;
    std::uint64_t next_seq = 1;
    std::map<std::uint64_t, Packet> in_flight;
    std::set<KeyframeKey> keyframes_held, landmarks_held;  ///< acknowledged
    std::set<KeyframeKey> keyframes_busy, landmarks_busy;  ///< in flight
  };
  void refill(Robot* r, double now) const;
  /// The next packet for `who` (empty when nothing new fits or the robot is not placed).
  std::optional<MapDownPacket> select(const GlobalMap& map, const DownlinkRecipient& who,
                                      const Robot& r, std::size_t byte_cap) const;

  DownlinkParams params_;
  std::uint64_t epoch_;
  std::map<Uuid, Robot> robots_;
  std::map<std::uint32_t, DownlinkRobotStats> stats_;
};

}  // namespace server
}  // namespace hermes
