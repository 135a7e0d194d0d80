// Agent side of exactly-once submap delivery: the map buffer (durable spool)
// plus the bandwidth monitor. Submaps are sent in (session, seq) order, at most
// `max_in_flight_bytes` unacknowledged on the wire at a time, resent after a
// timeout or a reconnect until acknowledged; acks free the buffer. The transport
// is a callback, so the same class drives the emulated link and ROS topics.
//
// Authentication (uplink.auth.*, frame_auth.h): with `enabled`, every frame is
// tagged with the robot's key when it is handed to the transport (the spool
// keeps the frames as encoded, so a spool written before a key change or before
// authentication was switched on is sent with the current key's tag). The tag
// adds kWireTagBytes to every frame sent.
#pragma once

#include <functional>
#include <map>
#include <optional>

#include "hermes/agent/bandwidth_monitor.h"
#include "hermes/agent/map_buffer.h"
#include "hermes/core/frame_auth.h"

namespace hermes::agent {

struct UplinkAuthParams {
  bool enabled = false;  ///< tag every frame with the robot's key
  /// The robot's key file; "{robot}" is replaced by the agent's name, "~/" by $HOME.
  std::string key_file = "~/.config/hermes/keys/{robot}.key";
  /// key_file for the agent `robot`.
  std::string keyFileFor(const std::string& robot) const;
};

struct UplinkParams {
  MapBufferParams buffer;
  BandwidthMonitorParams monitor;
  UplinkAuthParams auth;
  double max_in_flight_mbytes = 4.0;  ///< [MB] unacked bytes allowed on the wire

  Status read(const Config& c);
  Status validate() const;
  void write(ConfigWriter& w) const;
};

struct UplinkStats {
  std::size_t submitted = 0, sends = 0, resends = 0, acked = 0, refused = 0;
  std::size_t bytes_sent = 0;  ///< every byte handed to the transport, resends included
  std::size_t untagged = 0;    ///< authentication on, but a spooled frame could not be tagged
};

class UplinkSender {
 public:
  using Transport = std::function<void(std::uint32_t session, std::uint64_t seq,
                                       const std::vector<std::uint8_t>& frame)>;

  /// Opens the spool and, with p.auth.enabled, reads the key file of agent `robot`.
  static Expected<UplinkSender> create(const UplinkParams& p, Transport transport,
                                       const std::string& robot = "");

  /// Hands a new encoded submap over; error if the buffer refuses it (full).
  Status submit(std::uint32_t session, std::uint64_t seq, std::vector<std::uint8_t> frame,
                double now);
  /// Sends what may be sent at time `now` (call regularly).
  void poll(double now);
  /// Acknowledgement from the server (duplicates and unknown keys are fine).
  Status onAck(std::uint32_t session, std::uint64_t seq, double now);
  /// A relay robot took the submap into its durable spool (hop acknowledgement,
  /// relay_spool.h): the monitor measures the link to the relay with it, the
  /// submap no longer counts as this robot's backlog and is not sent again on a
  /// timeout (only after onReconnect), but it stays in the spool until the
  /// server's acknowledgement comes back through the relay (onAck).
  void onHandedOver(std::uint32_t session, std::uint64_t seq, double now);
  /// The link came back / the server restarted: resend everything unacked.
  void onReconnect();

  BandwidthMonitor& monitor() { return monitor_; }
  const BandwidthMonitor& monitor() const { return monitor_; }
  const MapBuffer& buffer() const { return buffer_; }
  MapBuffer& buffer() { return buffer_; }
  const UplinkStats& stats() const { return stats_; }
  /// Unacknowledged bytes (buffered, sent or not) not handed over to a relay:
  /// the coordinator's backlog.
  std::size_t backlogBytes() const { return buffer_.pendingBytes() - handed_bytes_; }
  /// Submaps a relay holds for this robot, waiting for the server's acknowledgement.
  std::size_t handedOverCount() const { return handed_.size(); }

 private:
  UplinkSender(UplinkParams p, MapBuffer buffer, Transport transport,
               std::optional<FrameKey> key);
  /// Bytes of a spooled frame as it goes on the wire (with the tag).
  std::size_t wireBytes(const std::vector<std::uint8_t>& frame) const;

  UplinkParams p_;
  std::optional<FrameKey> key_;
  MapBuffer buffer_;
  BandwidthMonitor monitor_;
  Transport transport_;
  std::map<std::pair<std::uint32_t, std::uint64_t>, std::uint64_t> send_ids_;
  std::map<std::pair<std::uint32_t, std::uint64_t>, std::size_t> in_flight_;
  std::uint64_t next_send_id_ = 0;
  std::map<std::pair<std::uint32_t, std::uint64_t>, std::size_t> handed_;  ///< to a relay: bytes
  std::size_t handed_bytes_ = 0;
  UplinkStats stats_;
};

}  // namespace hermes::agent
