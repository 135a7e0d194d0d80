// The offline runner's network for a scenario (scenario.h, link.scenario): one
// emulated link per scenario line, relay spools on the robots others reach,
// and every acknowledgement on its way back.
//
// Routes (chosen per frame at send time): the robot's server link while it is
// up; else, with relay.enabled, the first of its robot links that is up (the
// frame goes to that relay); else the server link (the frame waits in it),
// else the first robot link. What is in flight stays on its link.
//
// A relay's server link has one sender slot for its own submaps (0) and one per
// robot that can reach it; its coordinator (relay_split.h) sets the slots'
// shares every system.server_period_s from their credibility, with
// relay.min_mbitps guaranteed per relayed robot.
//
// Acknowledgements: the server's for a relayed submap goes back over the
// relay's server link to the relay (its spool frees the submap) and on over the
// origin's link to the relay (kept and sent again every relay.ack_retry_s while
// that link is down or drops it) to the origin, whose spool then frees it. The
// relay's hop acknowledgement (submap spooled) tells the origin's monitor how
// fast its link to the relay is.
#pragma once

#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <tuple>
#include <vector>

#include "hermes/agent/relay_spool.h"
#include "hermes/core/emulated_link.h"
#include "hermes/system/scenario.h"

namespace hermes::system {

/// What the network does to the robots and the server (set by the runner).
struct NetworkHooks {
  /// A submap of robot `origin` reached the server; returns whether it is acknowledged.
  std::function<bool(std::size_t origin, std::uint32_t session, std::uint64_t seq,
                     const std::vector<std::uint8_t>& frame, double arrival)>
      to_server;
  /// The server's acknowledgement reached the origin robot.
  std::function<void(std::size_t origin, std::uint32_t session, std::uint64_t seq, double t)> acked;
  /// A relay spooled the origin's submap (hop acknowledgement) and told it.
  std::function<void(std::size_t origin, std::uint32_t session, std::uint64_t seq, double t)> handed_over;
  /// A message of robot `origin` was lost on a link.
  std::function<void(std::size_t origin)> lost;
};

/// One sample of a relayed robot's stream on its relay's server link.
struct RelayedSample {
  double time_s = 0;
  std::string relay, origin;
  double served_kB = 0;            ///< served in the sample period
  double backlogged_up_s = 0;      ///< time it had bytes waiting while the link was up
  double weight = 0;               ///< its share beyond the guarantee when sampled
};

/// Per robot, over the whole run.
struct RobotTraffic {
  std::string robot;
  double own_bytes = 0;       ///< its own submaps put on its links (first hop)
  double relayed_bytes = 0;   ///< other robots' submaps it forwarded to the server
  std::size_t relayed_submaps = 0, hop_duplicates = 0;
  std::string relayed_by;     ///< relays that took its submaps (comma separated)
};

class RelayNetwork {
 public:
  static Expected<std::unique_ptr<RelayNetwork>> create(
      Scenario scenario, const agent::RelayParams& relay, const agent::UplinkParams& uplink,
      const std::vector<std::string>& robots, const std::string& spool_root, std::uint64_t seed,
      std::size_t packet_bytes, NetworkHooks hooks);

  /// The transport of robot `agent`: routes the frame at time `now`.
  void send(std::size_t agent, std::uint32_t session, std::uint64_t seq,
            const std::vector<std::uint8_t>& frame, double now);
  /// Links advanced to t: frames to the server and to relays handled.
  void deliver(double t);
  /// Acknowledgements due by t passed on.
  void acknowledge(double t);
  /// Relays forward what they may and (every period_s) their coordinators re-split.
  void poll(double t, double period_s);
  /// The server is back after a restart: relays resend what they hold.
  void onServerBack();
  /// Bytes the relays hold plus acknowledgements still on their way.
  std::size_t pendingWork() const;
  /// Appends one RelayedSample per relayed stream for the period ending at t.
  void sample(double t, double period_s);

  double ownBytes(std::size_t agent) const;
  /// Capacity of the robot's server link at t [kB/s] (nullopt without one).
  std::optional<double> serverCapacityKBps(std::size_t agent, double t) const;
  std::vector<RobotTraffic> traffic() const;
  const std::vector<RelayedSample>& relayedSamples() const { return samples_; }
  /// Lowest rate [Mbit/s] a relayed robot got while it had data waiting at its
  /// relay and the relay's uplink was up (sample periods with at least half of
  /// that); nullopt when nobody was relayed. `origin` non-empty: that robot only.
  std::optional<double> minRelayedMbitps(double period_s, const std::string& origin = "") const;
  const agent::RelaySpool* spool(std::size_t agent) const;
  const Scenario& scenario() const { return scenario_; }

 private:
  struct Link {
    const ScenarioLink* def = nullptr;
    std::size_t from = 0, to = 0;  ///< robot indices; to unused for server links
    std::unique_ptr<SharedLink> link;
    std::map<std::size_t, int> slots;  ///< server links: origin robot -> sender slot
  };
  struct Message {
    std::size_t link, origin;
    std::uint32_t session;
    std::uint64_t seq;
  };
  enum class AckKind { kServerToSender, kRelayToOrigin, kHop };
  struct PendingAck {
    double time;
    AckKind kind;
    std::size_t link, origin;  ///< kServerToSender: the server link it came back on
    std::uint32_t session;
    std::uint64_t seq;
  };
  RelayNetwork() = default;
  int route(std::size_t agent, double now) const;
  void queue(std::size_t link, int slot, std::size_t origin, std::uint32_t session,
             std::uint64_t seq, const std::vector<std::uint8_t>& frame, double now);
  void onArrival(const Link& l, const Message& m, const LinkDelivery& d);
  void resplit(std::size_t relay, double t);
  /// The link origin -> relay (index), or -1.
  int hopLink(std::size_t origin, std::size_t relay) const;

  Scenario scenario_;
  agent::RelayParams relay_;
  std::vector<std::string> robots_;
  std::vector<Link> links_;
  std::vector<int> server_link_;  ///< per robot: index into links_, or -1
  std::vector<std::unique_ptr<agent::RelaySpool>> spools_;  ///< per robot (null: relays nobody)
  std::vector<agent::StreamEvidence> own_evidence_;  ///< relays: their own stream
  std::set<std::tuple<std::size_t, std::uint32_t, std::uint64_t>> own_sent_;  ///< relays: (robot, session, seq)
  std::vector<RobotTraffic> traffic_;
  std::map<std::uint64_t, Message> messages_;
  std::uint64_t next_message_ = 0;
  std::vector<PendingAck> acks_;
  NetworkHooks hooks_;
  double now_ = 0, next_split_ = 0;
  std::map<std::pair<std::size_t, int>, std::pair<double, double>> last_served_;  ///< (link, slot) -> served, backlogged
  std::vector<RelayedSample> samples_;
};

}  // namespace hermes::system
