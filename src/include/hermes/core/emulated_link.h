// An emulated network bottleneck on a simulated clock, shared by several senders
// (the server's downlink that all agents contend for). Messages are split into
// packets served round-robin across senders at the trace's rate; a message
// arrives one latency after its last byte left, or is lost with the trace's loss
// probability (it still consumed its airtime). Deterministic for a seed.
//
// Shares (setShare, how a relay robot divides its uplink between its own map and
// the robots it relays, like `tc htb` classes): once any share is set, a sender
// with a guaranteed rate is served first while its token bucket (refilled at
// that rate, two packets deep) holds a packet, and the rest of the link goes to
// the senders with data in proportion to their weights (weighted fair queueing
// by virtual time). Work-conserving: a sender without data leaves its share to
// the others. Without shares the senders are served round robin.
#pragma once

#include <cstdint>
#include <deque>
#include <memory>
#include <random>
#include <vector>

#include "hermes/core/link_trace.h"

namespace hermes {

struct LinkMessage {
  int sender = 0;
  std::uint64_t id = 0;      ///< caller's id (e.g. submap seq)
  std::size_t bytes = 0;     ///< exact size on the wire
  std::shared_ptr<const std::vector<std::uint8_t>> payload;  ///< optional
  double send_time = 0;      ///< [s] simulated
};

struct LinkDelivery {
  LinkMessage message;
  double arrival_time = 0;   ///< [s] when the receiver has it
  bool lost = false;
};

class SharedLink {
 public:
  SharedLink(LinkTrace trace, int senders, std::uint64_t seed, std::size_t packet_bytes = 1500);

  /// Queues a message at simulated time `now` (must not go back in time).
  void send(LinkMessage msg, double now);
  /// Advances to time t; returns the messages that completed by then (lost ones
  /// flagged), ordered by arrival time.
  std::vector<LinkDelivery> advanceTo(double t);
  /// An acknowledgement sent back at `now`: its arrival time, or <0 if lost.
  double ackArrival(double now);

  /// Sets `sender`'s share (see above): weight > 0, guaranteed_Bps >= 0 [byte/s].
  void setShare(int sender, double weight, double guaranteed_Bps);

  std::size_t queuedBytes(int sender) const;
  /// Bytes of `sender` served so far, the packet on the wire counted as it goes.
  double servedBytes(int sender) const { return served_[sender]; }
  /// Seconds during which `sender` had bytes queued and the link was up.
  double backloggedUpSeconds(int sender) const { return backlogged_up_s_[sender]; }
  /// Bytes of `sender` that finished transmission (lost or not) so far.
  std::size_t transmittedBytes(int sender) const { return transmitted_[sender]; }
  double now() const { return now_; }
  const LinkTrace& trace() const { return trace_; }

 private:
  struct InFlight {
    LinkMessage msg;
    std::size_t remaining;
  };
  struct Share {
    double weight = 1, guaranteed_Bps = 0;
    double tokens = 0, refilled_at = 0;  ///< [byte], [s]
    double vtime = 0;                    ///< weighted bytes served beyond the guarantee
  };
  void simulateTo(double t);
  void completeMessage(int sender, double t);
  /// Next sender to serve a packet (-1: nothing queued): round robin, or by shares.
  int pickSender();
  int pickByShares();
  bool draw(double p);

  LinkTrace trace_;
  std::vector<std::deque<InFlight>> queues_;
  std::vector<std::size_t> transmitted_;
  std::vector<double> served_, backlogged_up_s_;
  std::vector<Share> shares_;
  bool use_shares_ = false;
  bool current_guaranteed_ = false;    // the packet being served uses the guarantee
  std::vector<LinkDelivery> pending_;  // completed, waiting for their arrival time
  std::size_t packet_bytes_;
  std::size_t packet_left_ = 0;        // bytes left of the packet being served
  int current_ = -1;                   // sender whose packet is being served
  int rr_next_ = 0;
  double now_ = 0;
  std::mt19937_64 rng_;
};

}  // namespace hermes
