// Agents, sessions, deduplication, stats and the world-frame rule.
#include "hermes/server/bookkeeper.h"

#include <algorithm>
#include <cmath>

namespace hermes {

namespace {
bool isNil(const Uuid& u) {
  return std::all_of(u.begin(), u.end(), [](std::uint8_t b) { return b == 0; });
}
}  // namespace

Status BookkeeperParams::read(const Config& c, const std::string& p) {
  for (auto s : {c.get(p + "require_registration", &require_registration),
                 c.get(p + "anchor_min_keyframes", &anchor_min_keyframes),
                 c.get(p + "anchor_wait_s", &anchor_wait_s),
                 c.get(p + "stale_after_s", &stale_after_s)})
    if (!s) return s;
  return validate();
}

void BookkeeperParams::write(ConfigWriter& w, const std::string& p) const {
  w.set(p + "require_registration", require_registration);
  w.set(p + "anchor_min_keyframes", anchor_min_keyframes);
  w.set(p + "anchor_wait_s", anchor_wait_s);
  w.set(p + "stale_after_s", stale_after_s);
}

Status BookkeeperParams::validate() const {
  if (anchor_min_keyframes < 0)
    return Error{"server.bookkeeper.anchor_min_keyframes must be >= 0, got " +
                 std::to_string(anchor_min_keyframes)};
  if (!std::isfinite(anchor_wait_s))
    return Error{"server.bookkeeper.anchor_wait_s must be finite (< 0: wait for every agent)"};
  if (!(stale_after_s >= 0))
    return Error{"server.bookkeeper.stale_after_s must be >= 0, got " +
                 std::to_string(stale_after_s)};
  if (!(relocalisation_timeout_s >= 0) || !std::isfinite(relocalisation_timeout_s))
    return Error{"server.relocalisation_timeout_s must be finite and >= 0, got " +
                 std::to_string(relocalisation_timeout_s)};
  return Status::Ok();
}

SubmapArrival SubmapArrival::of(const Submap& submap, std::size_t bytes) {
  SubmapArrival a;
  a.header = submap.header;
  a.bytes = bytes;
  a.keyframes = submap.windowKeyframeCount();  // extensions add no keyframe
  a.landmarks = submap.landmarks.size();
  a.observations = submap.observationCount();
  return a;
}

const char* toString(SessionAnchor a) {
  switch (a) {
    case SessionAnchor::kNone: return "none";
    case SessionAnchor::kWorld: return "world";
    case SessionAnchor::kLoop: return "loop";
  }
  return "?";
}

int AgentStats::relocalisedSessions() const {
  return static_cast<int>(std::count_if(sessions.begin(), sessions.end(),
                                        [](const auto& s) { return s.second.relocalised; }));
}

int AgentStats::newRobotSessions() const {
  return static_cast<int>(std::count_if(sessions.begin(), sessions.end(),
                                        [](const auto& s) { return s.second.reported_new; }));
}

double AgentStats::successRate() const {
  const double total = static_cast<double>(submaps_accepted + submaps_missing);
  return total > 0 ? static_cast<double>(submaps_accepted) / total : 0.0;
}

double AgentStats::bytesPerSecond() const {
  const double span = last_time - first_time;
  return span > 0 ? static_cast<double>(bytes_accepted) / span : 0.0;
}

double AgentStats::observationsPerLandmark() const {
  return landmarks > 0 ? static_cast<double>(observations) / static_cast<double>(landmarks) : 0.0;
}

Bookkeeper::Bookkeeper(BookkeeperParams params) : params_(std::move(params)) {
  Status s = params_.validate();
  HERMES_CHECK(s.ok(), s.error());
}

std::string Bookkeeper::describe(RobotId robot) const {
  if (robot >= agents_.size()) return "agent " + std::to_string(robot) + " (unknown)";
  return "agent " + std::to_string(robot) + " (uuid " + toString(agents_[robot].uuid) + ")";
}

Expected<RobotId> Bookkeeper::registerAgent(const Uuid& uuid, double now, const std::string& name) {
  if (isNil(uuid)) return Error{"bookkeeper: cannot register the nil uuid"};
  auto it = robot_of_.find(uuid);
  if (it != robot_of_.end()) {  // reconnect: same robot id
    if (!name.empty()) agents_[it->second].name = name;
    return it->second;
  }
  const auto robot = static_cast<RobotId>(agents_.size());
  AgentStats a;
  a.robot = robot;
  a.uuid = uuid;
  a.name = name.empty() ? "agent_" + std::to_string(robot) : name;
  a.first_time = a.last_time = -1;
  (void)now;
  agents_.push_back(std::move(a));
  robot_of_[uuid] = robot;
  return robot;
}

std::map<Uuid, Uuid> Bookkeeper::sealAsPrior() {
  std::map<Uuid, Uuid> renamed;
  robot_of_.clear();
  for (AgentStats& a : agents_) {
    const Uuid old = a.uuid;
    a.uuid = agentUuid("prior:" + toString(old));  // another prior's prior agent: another uuid again
    a.name = kPriorPrefix + (a.name.empty() ? toString(old) : a.name);
    robot_of_[a.uuid] = a.robot;
    renamed[old] = a.uuid;
  }
  return renamed;
}

bool Bookkeeper::isPrior(RobotId robot) const {
  return robot < agents_.size() && agents_[robot].name.rfind(kPriorPrefix, 0) == 0;
}

std::optional<RobotId> Bookkeeper::robotOf(const Uuid& uuid) const {
  auto it = robot_of_.find(uuid);
  if (it == robot_of_.end()) return std::nullopt;
  return it->second;
}

ArrivalDecision Bookkeeper::onArrival(const SubmapArrival& arrival, double now) {
  ArrivalDecision d;
  const SubmapHeader& h = arrival.header;
  const std::string who = "submap (uuid " + toString(h.agent) + ", session " +
                          std::to_string(h.session) + ", seq " + std::to_string(h.seq) + ")";
  if (isNil(h.agent)) {
    d.reason = who + ": nil agent uuid";
    return d;
  }
  auto known = robotOf(h.agent);
  if (!known) {
    if (params_.require_registration) {
      d.reason = who + ": agent uuid " + toString(h.agent) + " is not registered";
      return d;
    }
    auto r = registerAgent(h.agent, now);
    if (!r) {
      d.reason = who + ": " + r.error();
      return d;
    }
    known = *r;
    d.new_agent = true;
  }
  d.robot = *known;
  AgentStats& a = agents_[d.robot];
  ++a.submaps_received;
  a.bytes_received += arrival.bytes;
  if (a.first_time < 0) a.first_time = now;
  a.last_time = std::max(a.last_time, now);
  d.acknowledge = true;

  SeqTracker& seqs = seqs_[{d.robot, h.session}];
  if (seqs.seen.count(h.seq)) {
    ++a.submaps_duplicate;
    d.verdict = ArrivalVerdict::kDuplicate;
    d.reason = who + " of " + describe(d.robot) + " was already received";
    return d;
  }
  const bool first_submap = a.sessions.empty();
  if (!first_submap && h.session < a.current_session &&
      now - a.current_session_since > params_.stale_after_s) {
    ++a.submaps_stale;
    d.verdict = ArrivalVerdict::kStale;
    d.reason = who + " of " + describe(d.robot) + " belongs to superseded session " +
               std::to_string(h.session) + " (current " + std::to_string(a.current_session) +
               " since " + std::to_string(now - a.current_session_since) + " s)";
    return d;
  }
  if (first_submap || h.session > a.current_session) {
    d.new_session = true;
    a.current_session = h.session;
    a.current_session_since = now;
    a.anchored = false;  // the new session knows nothing of the old one's place
    a.T_W_A = SE3::identity();
  }

  // Accept. Missing = holes between the lowest and highest accepted seq.
  SessionStats& s = a.sessions[h.session];
  const std::uint64_t holes_before =
      s.submaps_accepted ? (s.highest_seq - s.lowest_seq + 1) - s.submaps_accepted : 0;
  seqs.seen.insert(h.seq);
  if (s.submaps_accepted == 0) {
    s.lowest_seq = s.highest_seq = h.seq;
    s.first_time = now;
  }
  s.lowest_seq = std::min(s.lowest_seq, h.seq);
  s.highest_seq = std::max(s.highest_seq, h.seq);
  ++s.submaps_accepted;
  s.keyframes += arrival.keyframes;
  s.last_time = std::max(s.last_time, now);
  const std::uint64_t holes_after = (s.highest_seq - s.lowest_seq + 1) - s.submaps_accepted;
  a.submaps_missing = a.submaps_missing + holes_after - holes_before;

  ++a.submaps_accepted;
  a.bytes_accepted += arrival.bytes;
  a.keyframes += arrival.keyframes;
  a.landmarks += arrival.landmarks;
  a.observations += arrival.observations;
  d.verdict = ArrivalVerdict::kAccept;
  return d;
}

bool Bookkeeper::isDuplicate(RobotId robot, std::uint32_t session, std::uint64_t seq) const {
  auto it = seqs_.find({robot, session});
  return it != seqs_.end() && it->second.seen.count(seq) > 0;
}

Status Bookkeeper::markApplied(RobotId robot, std::uint32_t session, std::uint64_t seq) {
  if (robot >= agents_.size())
    return Error{"bookkeeper: markApplied for unknown robot id " + std::to_string(robot)};
  auto it = seqs_.find({robot, session});
  if (it == seqs_.end() || !it->second.seen.count(seq))
    return Error{"bookkeeper: " + describe(robot) + " session " + std::to_string(session) +
                 " seq " + std::to_string(seq) + " was never accepted"};
  if (!applied_.insert({robot, session, seq}).second)
    return Error{"bookkeeper: " + describe(robot) + " session " + std::to_string(session) +
                 " seq " + std::to_string(seq) + " was already applied"};
  ++agents_[robot].submaps_applied;
  return Status::Ok();
}

std::optional<RobotId> Bookkeeper::selectWorld(const std::function<double(RobotId)>& credibility,
                                               const std::function<std::size_t(RobotId)>& group) {
  if (world_) return world_;
  std::vector<RobotId> qualified;
  const double now = clock();
  for (const AgentStats& a : agents_) {
    if (a.keyframes >= static_cast<std::uint64_t>(params_.anchor_min_keyframes)) qualified.push_back(a.robot);
  }
  if (qualified.empty()) return std::nullopt;
  if (!first_qualified_s_) first_qualified_s_ = now;
  const auto size = [&](RobotId r) { return group ? std::max<std::size_t>(group(r), 1) : 1; };
  std::size_t largest = 1;
  for (RobotId r : qualified) largest = std::max(largest, size(r));
  const bool all = qualified.size() == agents_.size();
  const bool waited = params_.anchor_wait_s >= 0 && now - *first_qualified_s_ >= params_.anchor_wait_s;
  std::vector<RobotId> candidates;
  if (params_.anchor_wait_s < 0) {  // the old rule: every agent qualified, loops aside
    if (all) candidates = qualified;
  } else if (largest > 1 || waited || (all && agents_.size() == 1)) {
    for (RobotId r : qualified)
      if (size(r) == largest) candidates.push_back(r);
  }
  if (candidates.empty()) return std::nullopt;
  RobotId best = candidates.front();
  double best_c = credibility ? credibility(best) : 0.0;
  for (RobotId r : candidates) {
    const double c = credibility ? credibility(r) : 0.0;
    if (c > best_c) {
      best_c = c;
      best = r;
    }
  }
  world_ = best;
  // The robot's first session defines the world: the map its loops tie to the
  // others; a later session (restart, map reset) re-localises against it.
  AgentStats& w = agents_[best];
  if (!w.sessions.empty()) {
    w.sessions.begin()->second.anchored_by = SessionAnchor::kWorld;
    w.sessions.begin()->second.anchored_at = now;
  }
  if (w.sessions.empty() || w.sessions.begin()->first == w.current_session) {
    w.anchored = true;
    w.T_W_A = SE3::identity();
  }
  return world_;
}

Status Bookkeeper::markAnchored(RobotId robot, const SE3& T_W_A) {
  if (robot >= agents_.size())
    return Error{"bookkeeper: markAnchored for unknown robot id " + std::to_string(robot)};
  return markSessionAnchored(robot, agents_[robot].current_session, SessionAnchor::kLoop, T_W_A);
}

Status Bookkeeper::markSessionAnchored(RobotId robot, std::uint32_t session, SessionAnchor by,
                                       const SE3& T_W_A) {
  if (robot >= agents_.size())
    return Error{"bookkeeper: markSessionAnchored for unknown robot id " + std::to_string(robot)};
  AgentStats& a = agents_[robot];
  auto it = a.sessions.find(session);
  if (it == a.sessions.end())
    return Error{"bookkeeper: cannot anchor " + describe(robot) + " session " +
                 std::to_string(session) + ": no submap of it was accepted"};
  if (!world_)
    return Error{"bookkeeper: cannot anchor " + describe(robot) +
                 ": the world frame is not fixed yet"};
  SessionStats& s = it->second;
  const bool world_session = s.anchored_by == SessionAnchor::kWorld;
  // Only the session selectWorld() chose defines the world: a later session of
  // the world robot knows nothing of it and needs loops like any other.
  if (by == SessionAnchor::kWorld && !world_session)
    return Error{"bookkeeper: " + describe(robot) + " session " + std::to_string(session) +
                 " does not define the world frame"};
  if ((world_session || by == SessionAnchor::kWorld) &&
      (!T_W_A.translation().isZero(1e-9) || rotationAngle(T_W_A.rotation()) > 1e-9))
    return Error{"bookkeeper: " + describe(robot) + " session " + std::to_string(session) +
                 " defines the world frame; its T_W_A must stay identity"};
  if (!T_W_A.translation().allFinite() || !T_W_A.quat().coeffs().allFinite())
    return Error{"bookkeeper: non-finite T_W_A for " + describe(robot)};
  if (s.anchored_by == SessionAnchor::kNone) {
    s.anchored_by = by;
    s.anchored_at = clock();
    const bool later = session != a.sessions.begin()->first;
    if (later && by == SessionAnchor::kLoop) {
      s.relocalised = true;
      s.reported_new = false;
    }
  }
  if (session == a.current_session) {
    a.anchored = true;
    a.T_W_A = T_W_A;
  }
  return Status::Ok();
}

std::vector<std::pair<RobotId, std::uint32_t>> Bookkeeper::checkRelocalisation(double now) {
  std::vector<std::pair<RobotId, std::uint32_t>> reported;
  for (AgentStats& a : agents_) {
    if (a.sessions.size() < 2) continue;
    for (auto it = std::next(a.sessions.begin()); it != a.sessions.end(); ++it) {
      SessionStats& s = it->second;
      if (s.anchored_by != SessionAnchor::kNone || s.reported_new) continue;
      if (now - s.first_time < params_.relocalisation_timeout_s) continue;
      s.reported_new = true;
      reported.emplace_back(a.robot, it->first);
    }
  }
  return reported;
}

double Bookkeeper::clock() const {
  double now = -1;  // a prior map's arrivals are another mission's clock
  for (const AgentStats& a : agents_)
    if (a.name.rfind(kPriorPrefix, 0) != 0) now = std::max(now, a.last_time);
  return now;
}

std::optional<std::uint32_t> Bookkeeper::worldSession() const {
  if (!world_) return std::nullopt;
  const AgentStats& w = agents_[*world_];
  for (const auto& [id, s] : w.sessions)
    if (s.anchored_by == SessionAnchor::kWorld) return id;
  return w.current_session;  // no submap accepted (anchor_min_keyframes 0)
}

bool Bookkeeper::anchored(RobotId robot) const {
  return robot < agents_.size() && agents_[robot].anchored;
}

std::optional<SE3> Bookkeeper::T_W_A(RobotId robot) const {
  if (!anchored(robot)) return std::nullopt;
  return agents_[robot].T_W_A;
}

const AgentStats* Bookkeeper::stats(RobotId robot) const {
  return robot < agents_.size() ? &agents_[robot] : nullptr;
}

std::vector<RobotId> Bookkeeper::robots() const {
  std::vector<RobotId> out;
  for (RobotId r = 0; r < agents_.size(); ++r) out.push_back(r);
  return out;
}

}  // namespace hermes
