// The relay robot's forwarding on a real uplink (ROS topics, a radio): links
// without shares, unlike the offline runner's emulated ones (relay_network.h,
// SharedLink::setShare). It owns the RelaySpool (per-origin durable spools,
// exactly once end to end, relay_spool.h) and paces what the spool's senders
// hand out, one token bucket per relayed robot, at the rate the relay's
// coordinator gives it (relay_split.h), re-split every `split_period_s`:
//
//   rate_i = guaranteed_i + weight_i * max(0, C - sum_j guaranteed_j)
//
// C: the relay's uplink estimate [byte/s] (its own bandwidth monitor; 0 in an
// outage or before a sample, when the relayed robots get their guarantees,
// relay.min_mbitps each); the sum runs over relayed robots with data held.
// The relay's own windows are not paced: its coordinator sizes them on what its
// monitor measures, i.e. on what the relayed streams leave of the link, and
// its own stream's evidence (onOwnFrame) weighs in the split as in the runner.
// A bucket holds at most one second of its rate; a frame goes when the bucket
// is not in debt (a frame larger than a second's worth goes and is paid after).
//
// Thread-safe: every call takes the forwarder's lock; `send` is called under
// it and must not call back (publishing a message is fine).
#pragma once

#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <vector>

#include "hermes/agent/relay_spool.h"

namespace hermes::agent {

class RelayForwarder {
 public:
  using Send = RelaySpool::Forward;

  /// What the relay does for one origin (status reports, tests).
  struct OriginState {
    std::string origin;
    RelaySpool::OriginStats stats;
    std::size_t pending = 0;        ///< submaps held, waiting for the server's acknowledgement
    std::size_t pending_bytes = 0;
    std::size_t waiting = 0;        ///< submaps handed out by the spool, not yet paced onto the uplink
    double rate_Bps = 0;            ///< [byte/s] pace set by the last split
    double weight = 0;              ///< share beyond the guarantees (last split)
    double forwarded_bytes = 0;     ///< put on the uplink, resends included
    std::size_t forwarded = 0;
  };

  /// Opens the spool folder DIR (relay_spool.h: a restarted relay forwards
  /// what it held) for the relayed robots `origins` (a submap of another robot
  /// is refused). Errors: invalid params or names, DIR unusable.
  static Expected<std::unique_ptr<RelayForwarder>> open(const std::string& dir,
                                                        const std::vector<std::string>& origins,
                                                        const RelayParams& relay,
                                                        const UplinkParams& uplink,
                                                        double split_period_s, Send send);

  /// A submap of `origin` arrived (the hop). kStored / kAlreadyHeld: acknowledge
  /// the hop; kAlreadyAcked: answer with the server's acknowledgement. Errors
  /// (nothing stored, no answer): an origin this relay does not serve, a frame
  /// of another robot (its routing uuid is not `origin`'s), RelaySpool::offer's.
  Expected<RelaySpool::Offer> offer(const std::string& origin, std::uint32_t session,
                                    std::uint64_t seq, std::vector<std::uint8_t> frame, double now);
  /// The server acknowledged (session, seq) of `origin`: freed, no longer paced.
  /// False when the relay did not hold it.
  bool onServerAck(const std::string& origin, std::uint32_t session, std::uint64_t seq, double now);
  /// The relay sent a submap of its own (its stream's credibility evidence;
  /// a resend of the same (session, seq) counts as a duplicate).
  void onOwnFrame(std::uint32_t session, std::uint64_t seq, const std::vector<std::uint8_t>& frame,
                  double now);
  /// Re-splits when due, lets the spool hand out what it may and forwards what
  /// the buckets allow. `uplink_Bps`: the relay's uplink estimate [byte/s].
  void poll(double now, double uplink_Bps);
  /// The relay's uplink came back / the server restarted: everything held is sent again.
  void onReconnect();

  /// The robots it serves and those whose folder an earlier run left in DIR
  /// (their submaps are forwarded too; no new ones are taken), in name order.
  std::vector<std::string> origins() const;
  /// The origin whose agentUuid string is `uuid`, or "" when not served here.
  std::string originOfUuid(const std::string& uuid) const;
  std::vector<OriginState> states() const;

 private:
  struct Waiting {
    std::uint32_t session;
    std::uint64_t seq;
    std::vector<std::uint8_t> frame;
  };
  struct Bucket {
    std::deque<Waiting> queue;
    std::set<std::pair<std::uint32_t, std::uint64_t>> keys;  ///< in queue
    double rate = 0, weight = 0, tokens = 0, last_t = -1;
    double forwarded_bytes = 0;
    std::size_t forwarded = 0;
  };
  RelayForwarder(RelayParams relay, double split_period_s, Send send)
      : relay_(relay), split_period_s_(split_period_s), send_(std::move(send)) {}
  void resplit(double now, double uplink_Bps);

  mutable std::mutex mu_;
  RelayParams relay_;
  double split_period_s_;
  Send send_;
  std::unique_ptr<RelaySpool> spool_;
  std::set<std::string> served_;                  ///< the origins offers are taken from
  std::map<std::string, Bucket> buckets_;          ///< served origins + earlier runs' spool folders
  std::map<std::string, std::string> uuid_to_origin_;
  StreamEvidence own_;
  std::set<std::pair<std::uint32_t, std::uint64_t>> own_sent_;
  double next_split_ = -1;
};

/// "uav1,uav2" -> {"uav1", "uav2"}: a comma-separated list of robot names
/// (spaces around names ignored; each a usable folder name, no repeats).
/// Empty in, empty out.
Expected<std::vector<std::string>> parseRobotList(const std::string& list);

}  // namespace hermes::agent
