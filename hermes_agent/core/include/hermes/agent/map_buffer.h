// The agent's map buffer (DESIGN §3): encoded submaps waiting for their
// acknowledgement, spooled on disk so that nothing is lost when the link drops
// or the agent process restarts.
//
// Spool file: append-only records [magic u32 'HSP1'][type u8][pad u8×3]
// [session u32][seq u64][length u32][crc32 u32 of header fields + payload]
// [payload]. DATA records carry a submap frame, ACK records free one. Each append
// is fsync'ed (configurable) before push() returns, so a returned OK means the
// submap is durable. On open the spool is replayed; a torn record at the tail
// (a crash mid-append) is cut off and reported. When acknowledged records make
// up more than half of the file, it is compacted (rewritten, atomically renamed).
//
// Policy when full: push() refuses a submap that would take the pending bytes
// over `max_bytes` and returns an error; nothing already stored is dropped. The
// caller (the coordinator) then defers its window.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "hermes/core/config.h"

namespace hermes::agent {

struct MapBufferParams {
  std::string dir;                       ///< spool directory (created if missing)
  double max_mbytes = 256.0;             ///< [MB] cap on pending (unacked) bytes
  bool fsync = true;                     ///< fsync every append
  double resend_timeout_s = 10.0;        ///< [s] resend an unacked submap after this,
                                         ///< doubled per resend of it (at most x8): a
                                         ///< link far slower than believed is not flooded

  Status read(const Config& c);
  Status validate() const;
  void write(ConfigWriter& w) const;
};

struct BufferedSubmap {
  std::uint32_t session = 0;
  std::uint64_t seq = 0;
  std::vector<std::uint8_t> frame;  ///< the exact bytes to send
  double last_sent = -1.0;          ///< [s] simulated/wall time of the last send, <0 never
  int sends = 0;
};

class MapBuffer {
 public:
  /// Opens (and replays) the spool in params.dir.
  static Expected<MapBuffer> open(const MapBufferParams& params);
  MapBuffer(MapBuffer&& o) noexcept;
  MapBuffer& operator=(MapBuffer&& o) noexcept;
  MapBuffer(const MapBuffer&) = delete;
  MapBuffer& operator=(const MapBuffer&) = delete;
  ~MapBuffer();

  /// Stores a submap durably. Error when full (see policy) or on I/O failure;
  /// a duplicate (session, seq) is an error too.
  Status push(std::uint32_t session, std::uint64_t seq, std::vector<std::uint8_t> frame);
  /// Frees an acknowledged submap (unknown keys are ignored: duplicate acks).
  Status ack(std::uint32_t session, std::uint64_t seq);

  /// The oldest pending submap that was never sent or whose resend timeout
  /// expired at time `now`; nullptr if none. Order: (session, seq).
  BufferedSubmap* nextToSend(double now);
  void markSent(std::uint32_t session, std::uint64_t seq, double now);
  /// The pending submap (session, seq), or nullptr.
  const BufferedSubmap* find(std::uint32_t session, std::uint64_t seq) const {
    auto it = pending_.find({session, seq});
    return it == pending_.end() ? nullptr : &it->second;
  }
  /// Keeps a pending submap from being sent again until resetSendTimes() (a relay
  /// holds it durably and forwards it; its acknowledgement frees it as usual).
  void hold(std::uint32_t session, std::uint64_t seq);
  /// Makes every pending submap eligible for sending again (after a reconnect).
  void resetSendTimes();

  std::size_t pendingCount() const { return pending_.size(); }
  /// (session, seq) of every pending submap, in sending order.
  std::vector<std::pair<std::uint32_t, std::uint64_t>> pendingKeys() const {
    std::vector<std::pair<std::uint32_t, std::uint64_t>> keys;
    for (const auto& [key, s] : pending_) keys.push_back(key);
    return keys;
  }
  std::size_t pendingBytes() const { return pending_bytes_; }
  std::size_t fileBytes() const { return file_bytes_; }
  /// Bytes cut off a torn tail record when the spool was opened (0 normally).
  std::size_t recoveredTornBytes() const { return torn_bytes_; }
  /// Next session number for this agent: persisted, increases on every call.
  Expected<std::uint32_t> newSession();
  /// Drops every pending submap (start without a previous run's backlog) and rewrites
  /// the spool file empty; returns how many were dropped. The session counter is kept
  /// (and raised to the highest dropped session), so newSession() still moves past every
  /// session this agent used: a reused (session, seq) would be taken by the server for a
  /// duplicate of the old run's submap, acknowledged and never applied.
  Expected<std::size_t> discardPending();

 private:
  explicit MapBuffer(MapBufferParams p);
  Status replay();
  Status append(std::uint8_t type, std::uint32_t session, std::uint64_t seq,
                const std::vector<std::uint8_t>& payload);
  Status compact();
  Status writeSession(std::uint32_t session);
  std::string spoolPath() const;

  MapBufferParams p_;
  std::map<std::pair<std::uint32_t, std::uint64_t>, BufferedSubmap> pending_;
  std::size_t pending_bytes_ = 0;
  std::size_t file_bytes_ = 0;
  std::size_t torn_bytes_ = 0;
  int fd_ = -1;
};

}  // namespace hermes::agent
