// The relay robot's side of relayed delivery (DESIGN §9 "relay"): submaps of
// robots out of the server's reach, held durably per origin and forwarded over
// the relay's own uplink.
//
// Per origin robot: a spool folder DIR/<origin> (a MapBuffer, the same
// append-only, CRC'd, fsync'ed format as the robot's own) behind an
// UplinkSender that forwards the frames as they are (the origin's tag and
// routing untouched), resends them until the server acknowledges, and frees
// them on the acknowledgement. Exactly once, end to end:
//  * offer(): a new submap is stored before the relay acknowledges the hop
//    (kStored); one it already holds is not stored twice (kAlreadyHeld); one the
//    server already acknowledged through this relay is answered with that
//    acknowledgement at once (kAlreadyAcked). The origin keeps every submap in
//    its own spool until the server's acknowledgement comes back (onServerAck,
//    forwarded by the caller), so a relay lost with its disk costs nothing but
//    time: the origin resends through whatever route it has next.
//  * the server deduplicates by (agent, session, seq), so a submap that reaches
//    it twice (two relays, a relay restarted before it saw the ack) is applied once.
//  * a relay that restarts reopens every origin folder and forwards what it held.
#pragma once

#include <functional>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "hermes/agent/relay_split.h"
#include "hermes/agent/uplink_sender.h"

namespace hermes::agent {

class RelaySpool {
 public:
  using Forward = std::function<void(const std::string& origin, std::uint32_t session,
                                     std::uint64_t seq, const std::vector<std::uint8_t>& frame)>;
  enum class Offer { kStored, kAlreadyHeld, kAlreadyAcked };

  struct OriginStats {
    std::size_t stored = 0;         ///< submaps taken into the spool
    std::size_t duplicates = 0;     ///< offers of a submap already held or acknowledged
    std::size_t server_acked = 0;   ///< acknowledgements of the server passed on
    double bytes_received = 0;      ///< every byte offered, duplicates included
  };

  /// Opens DIR (created if missing) and every origin folder in it. `uplink`
  /// gives the spools' limits, fsync and resend timeout (authentication is not
  /// applied: the frames keep the origin's tag). `forward` sends a frame over
  /// the relay's uplink.
  static Expected<std::unique_ptr<RelaySpool>> open(const std::string& dir,
                                                    const UplinkParams& uplink, Forward forward);

  /// A submap of `origin` arrived at time `now`. Errors (nothing stored, no
  /// acknowledgement due): an origin name unusable as a folder name, a frame
  /// that is damaged or whose routing says another (session, seq), a full spool.
  Expected<Offer> offer(const std::string& origin, std::uint32_t session, std::uint64_t seq,
                        std::vector<std::uint8_t> frame, double now);
  /// The server acknowledged (session, seq) of `origin`: freed from the spool.
  /// False when the relay did not hold it (a duplicate acknowledgement).
  bool onServerAck(const std::string& origin, std::uint32_t session, std::uint64_t seq, double now);
  /// Forwards what may be sent at time `now` (call regularly).
  void poll(double now);
  /// The relay's uplink came back / the server restarted: resend everything held.
  void onReconnect();

  /// Origins with a spool, in name order.
  std::vector<std::string> origins() const;
  std::size_t pendingBytes() const;
  std::size_t pendingBytes(const std::string& origin) const;
  std::size_t pendingCount(const std::string& origin) const;
  /// Credibility evidence of `origin`'s stream (relay_split.h).
  RelayStream stream(const std::string& origin, double now) const;
  const OriginStats* stats(const std::string& origin) const;

 private:
  struct Origin {
    std::unique_ptr<UplinkSender> sender;
    std::set<std::pair<std::uint32_t, std::uint64_t>> acked;  ///< by the server, through here
    StreamEvidence evidence;
    OriginStats stats;
  };
  RelaySpool(std::string dir, UplinkParams uplink, Forward forward)
      : dir_(std::move(dir)), uplink_(std::move(uplink)), forward_(std::move(forward)) {}
  Expected<Origin*> originFor(const std::string& name);

  std::string dir_;
  UplinkParams uplink_;
  Forward forward_;
  std::map<std::string, Origin> origins_;
};

/// A robot name usable as a spool folder name: [A-Za-z0-9_.-], not "." or "..".
Status checkRobotName(const std::string& name);

}  // namespace hermes::agent
