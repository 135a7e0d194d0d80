// Server bookkeeping: agents, sessions, submap deduplication, per-agent stats
// and the global (world) frame rule.
//
// Agents: a uuid gets a robot id (0, 1, 2, ... in order of first contact) that
// stays the same across reconnects and restarts. Registration is implicit by
// default (the first submap of an unknown uuid registers it); with
// server.bookkeeper.require_registration = true an unknown uuid's submaps are
// rejected until registerAgent() was called (e.g. on a heartbeat / hello).
//
// Sessions: an agent that restarts or resets its map sends a higher session
// number. Keyframe keys are (robot id, session, keyframe id), so keyframe ids
// reused by the new session never collide with the old ones, whose data is
// kept. The current session is the highest one seen. A reconnect after an
// outage is not a new session: same robot id, same session, same anchoring.
//
// Re-localisation (per session, SessionStats::anchored_by): the session that
// defines the world frame is anchored by the world rule; any other session,
// also a later session of the world robot, is anchored only by verified loops
// to anchored trajectories (MapManager), never put at the origin. A later
// session of a known robot (it restarted or reset its map and no longer knows
// its old pose) that loops tie to the global map is re-localised; one that no
// loop tied within relocalisation_timeout_s (server.relocalisation_timeout_s)
// of its first arrival is reported as a new robot (checkRelocalisation; a loop
// that ties it later still re-localises it). Either way it keeps the robot id
// of its uuid. While a new session is not anchored, the robot (its current
// session) counts as not anchored.
//
// Arrival verdicts for (uuid, session, seq):
//   accept      first time seen (any order: out-of-order seqs are accepted and
//               the gaps are counted as missing until they arrive)
//   duplicate   already accepted: acknowledge again, do not apply
//   stale       a session older than the agent's current one, arriving more than
//               stale_after_s after the current session began (late spool
//               resends of an abandoned map): acknowledge, do not apply
//   rejected    unknown agent while registration is required, or a malformed
//               header (e.g. nil uuid): do not acknowledge
//
// Global frame: selectWorld() fixes the world frame (T_W_A = identity, anchored)
// on the first session of one of the agents that have accepted >=
// anchor_min_keyframes keyframes ("qualified"): among the qualified agents of the
// largest group that verified inter-robot loops tie together (a map that can merge
// at once; a robot alone is a group of one), the most credible. It is fixed once
// (a) a verified loop ties a qualified agent to another (a robot that stays small
// or stopped early no longer blocks everyone), or (b) anchor_wait_s passed since
// the first agent qualified (the latest arrival time is the clock; the wait
// restarts after a checkpoint restore), or (c) the only agent known qualifies.
// Fixing it as soon as every agent qualified, before any loop, could pick a robot
// that meets no one soon and leave the robots that already meet each other out of
// the map. anchor_wait_s < 0 keeps the oldest rule: once every agent qualified,
// the most credible, loops aside. Another agent is anchored by markAnchored(agent,
// T_W_A) when a verified loop ties it to an anchored agent.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <tuple>
#include <vector>

#include "hermes/core/delivery.h"
#include "hermes/core/config.h"
#include "hermes/core/geometry.h"
#include "hermes/core/map_types.h"
#include "hermes/core/status.h"

namespace hermes {
namespace server {
class ByteReader;
class ByteWriter;
}  // namespace server


struct BookkeeperParams {
  bool require_registration = false;
  int anchor_min_keyframes = 10;  ///< keyframes an agent must have sent to define the world
  double anchor_wait_s = 30.0;    ///< after this since the first qualified, fix it anyway (< 0: wait for all)
  double stale_after_s = 60.0;    ///< grace for late submaps of a superseded session [s]
  /// server.relocalisation_timeout_s (read by ServerParams): a later session of a
  /// known robot that no verified loop tied to the global map this long after its
  /// first arrival is reported as a new robot [s]
  double relocalisation_timeout_s = 60.0;
  Status read(const Config& config, const std::string& prefix = "server.bookkeeper.");
  void write(ConfigWriter& out, const std::string& prefix = "server.bookkeeper.") const;
  Status validate() const;
};

/// What the bookkeeper needs to know about an arriving submap.
struct SubmapArrival {
  SubmapHeader header;
  std::size_t bytes = 0;         ///< encoded size as received
  std::size_t keyframes = 0;
  std::size_t landmarks = 0;
  std::size_t observations = 0;  ///< landmark observations
  static SubmapArrival of(const Submap& submap, std::size_t bytes);
};

// ArrivalVerdict: hermes/core/delivery.h.

struct ArrivalDecision {
  ArrivalVerdict verdict = ArrivalVerdict::kRejected;
  RobotId robot = 0;
  bool new_agent = false;    ///< this arrival registered the agent
  bool new_session = false;  ///< first submap of a session higher than any before
  bool acknowledge = false;  ///< send an ack (accept, duplicate, stale)
  std::string reason;        ///< for duplicate / stale / rejected: names the agent (uuid)
};

/// How a session's trajectory got into the world frame.
enum class SessionAnchor : std::uint8_t {
  kNone = 0,   ///< not (yet) anchored
  kWorld = 1,  ///< defines the world frame (selectWorld)
  kLoop = 2,   ///< verified loops tied it to anchored trajectories
};
const char* toString(SessionAnchor a);

struct SessionStats {
  SessionAnchor anchored_by = SessionAnchor::kNone;
  double anchored_at = -1;    ///< arrival clock when anchored [s]
  bool relocalised = false;   ///< a later session of the robot, anchored by loops
  bool reported_new = false;  ///< a later session no loop tied within the timeout (so far)
  std::uint64_t submaps_accepted = 0;
  std::uint64_t highest_seq = 0;   ///< highest accepted seq
  std::uint64_t lowest_seq = 0;    ///< lowest accepted seq
  std::uint64_t keyframes = 0;
  double first_time = 0, last_time = 0;
};

struct AgentStats {
  RobotId robot = 0;
  Uuid uuid{};
  std::string name;
  std::uint32_t current_session = 0;
  double current_session_since = 0;       ///< when the current session first arrived [s]
  std::uint64_t submaps_received = 0;     ///< every arrival, including duplicates
  std::uint64_t submaps_accepted = 0;
  std::uint64_t submaps_applied = 0;
  std::uint64_t submaps_duplicate = 0;
  std::uint64_t submaps_stale = 0;
  std::uint64_t submaps_missing = 0;      ///< seq gaps not (yet) filled, over all sessions
  std::uint64_t bytes_received = 0;       ///< every arrival
  std::uint64_t bytes_accepted = 0;
  std::uint64_t keyframes = 0;            ///< in accepted submaps
  std::uint64_t landmarks = 0;
  std::uint64_t observations = 0;
  double first_time = -1, last_time = -1; ///< first / last arrival [s]
  bool anchored = false;
  SE3 T_W_A;                              ///< valid when anchored
  std::map<std::uint32_t, SessionStats> sessions;

  /// Accepted / (accepted + missing) seqs: delivery success as the server sees it.
  double successRate() const;
  /// Accepted bytes per second over [first_time, last_time] (0 for one arrival).
  double bytesPerSecond() const;
  /// Mean observations per landmark over accepted submaps.
  double observationsPerLandmark() const;
  /// Sessions re-localised / reported as a new robot now (SessionStats flags).
  int relocalisedSessions() const;
  int newRobotSessions() const;
};

/// Name prefix of the agents of a prior map (Bookkeeper::sealAsPrior).
inline constexpr const char* kPriorPrefix = "prior/";

/// Not thread-safe: the server's handler owns it and calls it from one thread.
class Bookkeeper {
 public:
  explicit Bookkeeper(BookkeeperParams params = {});

  /// Registers (or re-registers after reconnect) an agent; the robot id is stable.
  Expected<RobotId> registerAgent(const Uuid& uuid, double now, const std::string& name = "");
  std::optional<RobotId> robotOf(const Uuid& uuid) const;

  /// Decides what to do with an arriving submap and updates the stats.
  ArrivalDecision onArrival(const SubmapArrival& arrival, double now);
  /// The merger applied an accepted submap.
  Status markApplied(RobotId robot, std::uint32_t session, std::uint64_t seq);
  /// True if (robot, session, seq) was already accepted (a resend).
  bool isDuplicate(RobotId robot, std::uint32_t session, std::uint64_t seq) const;

  KeyframeKey key(RobotId robot, std::uint32_t session, KeyframeId id) const {
    return KeyframeKey{robot, session, id};
  }

  /// Fixes the world frame by the rule above: the candidate with the highest
  /// credibility (ties: lowest robot id) is anchored with T_W_A = identity.
  /// `group(r)`: how many agents verified inter-robot loops tie together with
  /// agent r, r included (empty function: every agent alone). Returns the world
  /// agent (also when it was fixed before), nullopt while waiting.
  std::optional<RobotId> selectWorld(const std::function<double(RobotId)>& credibility,
                                     const std::function<std::size_t(RobotId)>& group = nullptr);
  /// Anchors (or re-anchors) an agent's current session, whose frame a verified
  /// loop tied to the world (markSessionAnchored with kLoop).
  Status markAnchored(RobotId robot, const SE3& T_W_A);
  /// Session `session` of `robot` is anchored (`by` the world rule or loops) with
  /// T_W_A; a later session anchored by loops is re-localised. The first call per
  /// session decides `by`; T_W_A is the robot's when it is its current session.
  /// Errors: unknown robot or session, no world yet, a non-identity T_W_A for the
  /// world session, non-finite pose.
  Status markSessionAnchored(RobotId robot, std::uint32_t session, SessionAnchor by, const SE3& T_W_A);
  /// Reports as new robots the later sessions that no loop tied to the global
  /// map within relocalisation_timeout_s of their first arrival (`now`: arrival
  /// clock). Returns the (robot, session) pairs reported by this call.
  std::vector<std::pair<RobotId, std::uint32_t>> checkRelocalisation(double now);
  std::optional<RobotId> worldAgent() const { return world_; }
  /// The world agent's session that defines the world frame (its first).
  std::optional<std::uint32_t> worldSession() const;
  bool anchored(RobotId robot) const;
  std::optional<SE3> T_W_A(RobotId robot) const;

  const AgentStats* stats(RobotId robot) const;
  std::vector<RobotId> robots() const;
  const BookkeeperParams& params() const { return params_; }
  /// "agent 1 (uuid ...)" for messages.
  std::string describe(RobotId robot) const;

  /// A prior map (CheckpointParams::prior_map) was loaded: its agents become
  /// "prior/<name>" with a uuid derived from theirs, so a robot of this mission
  /// registers as a new robot even under the same name (its sessions and seqs
  /// start again) and is placed in the prior's world frame by loops. Returns
  /// old uuid -> new uuid.
  std::map<Uuid, Uuid> sealAsPrior();
  /// An agent of a prior map (its name, kept in checkpoints, says so).
  bool isPrior(RobotId robot) const;
  /// Checkpoint (server_checkpoint.h): agents, sessions, accepted and applied seqs, world.
  void save(server::ByteWriter* w) const;
  /// Into a bookkeeper that has seen nothing yet; the error names what is damaged.
  Status load(server::ByteReader* r);

 private:
  struct SeqTracker {
    std::set<std::uint64_t> seen;  ///< accepted seqs (small: one per 5 s window)
  };
  BookkeeperParams params_;
  std::map<Uuid, RobotId> robot_of_;
  std::vector<AgentStats> agents_;  ///< indexed by robot id
  std::map<std::pair<RobotId, std::uint32_t>, SeqTracker> seqs_;
  std::set<std::tuple<RobotId, std::uint32_t, std::uint64_t>> applied_;
  std::optional<RobotId> world_;
  std::optional<double> first_qualified_s_;  ///< arrival clock when an agent first qualified
  double clock() const;  ///< the latest arrival time over this mission's agents, not the prior's (-1 before any)
};

}  // namespace hermes
