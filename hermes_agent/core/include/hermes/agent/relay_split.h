// The relay's coordinator (paper §IV-C, §VII-B): a robot that carries other
// robots' submaps divides its uplink between its own windows and the backlog
// it relays, by credibility, with a guaranteed floor for every relayed robot.
//
// Per stream i on the relay's uplink (its own map, one per relayed robot):
//   TS_i = success_i * rate_i / max_j rate_j      transmission stability
//          (success: frames that arrived once / all arrivals, resends counted;
//           rate: bytes per second the stream brought to the relay)
//   MC_i = opl_i / max_j opl_j                     map connectivity
//          (opl: mean observations per landmark of the stream's submaps)
//   c_i  = w_ts * TS_i + w_mc * MC_i
// Shares: weight_i = max(c_i, kMinWeight) normalised to sum 1, then the relay's
// own weight raised to at least own_min_share (its map is never starved); each
// relayed robot is guaranteed min_mbitps (the link serves guarantees first and
// the rest by weight: SharedLink::setShare, like `tc htb` classes).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "hermes/core/config.h"

namespace hermes::agent {

/// The credibility weights: one pair of keys for the relay and the server's queue
/// (server.credibility, credibility.h), which score credibility alike.
constexpr const char* kCredibilityWts = "server.credibility.w_ts";
constexpr const char* kCredibilityWmc = "server.credibility.w_mc";

/// Keys relay.* and the credibility weights (kCredibilityWts, kCredibilityWmc).
struct RelayParams {
  bool enabled = true;          ///< a robot out of the server's reach hands its submaps to a robot it reaches
  double min_mbitps = 1.0;      ///< [Mbit/s] guaranteed uplink share per relayed robot with data waiting
  double own_min_share = 0.3;   ///< least fraction of the weights the relay's own map keeps
  double w_ts = 0.5;            ///< weight of transmission stability (kCredibilityWts)
  double w_mc = 0.5;            ///< weight of map connectivity (kCredibilityWmc)
  double ack_retry_s = 0.5;     ///< [s] an acknowledgement the link to the origin dropped is sent again after this

  Status read(const Config& c);
  Status validate() const;
  void write(ConfigWriter& w) const;
  double minBps() const { return min_mbitps * 1e6 / 8.0; }
};

/// What the relay knows of one stream on its uplink.
struct RelayStream {
  bool own = false;             ///< the relay's own map
  double success_rate = 1;      ///< [0, 1]
  double bytes_per_s = 0;       ///< brought to the relay
  double obs_per_landmark = 0;  ///< 0 = not known yet
};

struct StreamShare {
  double ts = 0, mc = 0, c = 0;  ///< credibility terms
  double weight = 0;             ///< share of the link beyond the guarantees (sum 1)
  double guaranteed_Bps = 0;     ///< [byte/s]
};

/// Collects a stream's evidence from the frames it brings to the relay.
class StreamEvidence {
 public:
  /// One frame arrived at time `now` [s]; `duplicate`: it had arrived before (a resend).
  void onFrame(const std::vector<std::uint8_t>& frame, double now, bool duplicate);
  RelayStream stream(double now, bool own) const;
  std::size_t frames() const { return frames_; }
  std::size_t duplicates() const { return duplicates_; }
  double bytes() const { return bytes_; }

 private:
  std::size_t frames_ = 0, duplicates_ = 0;
  double bytes_ = 0, first_t_ = -1;
  double landmarks_ = 0, observations_ = 0;
};

/// A stream's weight never falls below this (a robot without evidence yet still moves).
constexpr double kMinStreamWeight = 0.05;

/// Shares of `streams` (same order). Empty in, empty out.
std::vector<StreamShare> splitUplink(const RelayParams& p, const std::vector<RelayStream>& streams);

}  // namespace hermes::agent
