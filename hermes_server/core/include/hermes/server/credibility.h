// Credibility assessor (CSA) and the merge queue of pending submaps.
//
// Per agent a (DESIGN.md §5):
//   TS_a = success_rate_a * bw_a / max_b bw_b          transmission stability
//   MC_a = 1 if a has a verified loop, else opl_a / max_b opl_b
//          (opl = mean observations per landmark)       map connectivity
//   c_a  = w_TS * TS_a + w_MC * MC_a
// Pending submaps are merged in descending priority
//   p = c_agent(now) + aging_per_s * (now - arrival)
// (ties: earlier arrival first). Since every item ages at the same rate, a
// submap that arrived at t_s is served before every submap arriving after
// t_s + (w_TS + w_MC) / aging_per_s: it waits at most for the submaps already
// queued plus those arriving in that window (20 s with the defaults).
// Within one agent the order is always arrival order (same c, older = higher p),
// so each agent keeps a FIFO and pop() compares the agents' heads.
// With server.csa = off the queue is plain FIFO by arrival.
#pragma once

#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "hermes/core/config.h"
#include "hermes/server/bookkeeper.h"

namespace hermes {
namespace server {
class ByteReader;
class ByteWriter;
}  // namespace server

struct CredibilityParams {
  bool enabled = true;        ///< server.csa: on (credibility order) | off (FIFO)
  double w_ts = 0.5;          ///< weight of transmission stability
  double w_mc = 0.5;          ///< weight of map connectivity
  double aging_per_s = 0.05;  ///< priority gained per second waited [1/s]
  int history = 100000;       ///< pop records kept (oldest dropped)
  /// Reads server.csa and server.credibility.{w_ts, w_mc, aging_per_s, history}.
  Status read(const Config& config, const std::string& prefix = "server.");
  void write(ConfigWriter& out, const std::string& prefix = "server.") const;
  Status validate() const;
  /// Seconds after which a waiting submap outranks every later arrival.
  double agingWindowS() const { return aging_per_s > 0 ? (w_ts + w_mc) / aging_per_s : -1; }
};

/// What the CSA knows about an agent (from the bookkeeper and the loop closer).
struct AgentEvidence {
  double success_rate = 0;      ///< [0, 1]
  double bytes_per_s = 0;       ///< bandwidth actually used
  double obs_per_landmark = 0;  ///< mean observations per landmark
  bool has_loops = false;       ///< a verified loop involves the agent
  static AgentEvidence from(const AgentStats& stats, bool has_loops);
};

struct CredibilityScore {
  double ts = 0, mc = 0, c = 0;
};

struct PendingSubmap {
  RobotId agent = 0;
  std::uint32_t session = 0;
  std::uint64_t seq = 0;
  double arrival = 0;        ///< [s]
  std::uint64_t handle = 0;  ///< caller's reference to the stored submap
};

/// One merge decision, for logs and metrics.
struct PopRecord {
  PendingSubmap item;
  std::uint64_t order = 0;     ///< 0, 1, 2, ... merge order
  double popped_at = 0;        ///< [s]
  double waited_s = 0;
  CredibilityScore score;      ///< of item.agent at pop time
  double priority = 0;         ///< score.c + aging (csa on) or -arrival (off)
  std::size_t queue_size = 0;  ///< items waiting before the pop
};

/// Not thread-safe: the server pipeline owns it and calls it from one thread.
class CredibilityAssessor {
 public:
  explicit CredibilityAssessor(CredibilityParams params = {});

  void setEvidence(RobotId agent, const AgentEvidence& evidence);
  /// Refreshes every agent's evidence from the bookkeeper's stats.
  void updateFrom(const Bookkeeper& bookkeeper, const std::function<bool(RobotId)>& has_loops);
  /// Scores normalised over all agents with evidence (zero for unknown agents).
  CredibilityScore score(RobotId agent) const;
  std::map<RobotId, CredibilityScore> scores() const;

  void push(const PendingSubmap& item);
  /// Next submap to merge, or nullopt when the queue is empty.
  std::optional<PopRecord> pop(double now);
  std::size_t size() const { return size_; }
  bool empty() const { return size_ == 0; }

  const std::deque<PopRecord>& history() const { return history_; }
  void setLogger(std::function<void(const PopRecord&)> logger) { logger_ = std::move(logger); }
  const CredibilityParams& params() const { return params_; }
  /// The waiting submaps, per agent in arrival order.
  std::vector<PendingSubmap> pending() const;

  /// Checkpoint (server_checkpoint.h): the waiting submaps, merge order and
  /// history (evidence is refreshed from the bookkeeper before every pop).
  void save(server::ByteWriter* w) const;
  /// Into an empty queue; false on damaged input.
  bool load(server::ByteReader* r);

 private:
  struct Queued {
    PendingSubmap item;
    std::uint64_t push_order;
  };
  CredibilityParams params_;
  std::map<RobotId, AgentEvidence> evidence_;
  std::map<RobotId, std::deque<Queued>> queues_;
  std::size_t size_ = 0;
  std::uint64_t pushes_ = 0, pops_ = 0;
  std::deque<PopRecord> history_;
  std::function<void(const PopRecord&)> logger_;
};

}  // namespace hermes
