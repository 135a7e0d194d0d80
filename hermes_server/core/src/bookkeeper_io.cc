// Bookkeeper checkpoint: what it knows about every agent, field by field.
#include "hermes/server/bookkeeper.h"
#include "hermes/server/byte_codec.h"

#include <cmath>

namespace hermes {

namespace {

using server::ByteReader;
using server::ByteWriter;

void saveSession(ByteWriter* w, std::uint32_t id, const SessionStats& s) {
  w->pod(id);
  w->pod(static_cast<std::uint8_t>(s.anchored_by));
  w->pod(s.anchored_at);
  w->flag(s.relocalised);
  w->flag(s.reported_new);
  for (std::uint64_t v : {s.submaps_accepted, s.highest_seq, s.lowest_seq, s.keyframes}) w->pod(v);
  w->pod(s.first_time);
  w->pod(s.last_time);
}

bool loadSession(ByteReader* r, std::uint32_t* id, SessionStats* s) {
  std::uint8_t by = 0;
  if (!r->pod(id) || !r->pod(&by) || by > static_cast<std::uint8_t>(SessionAnchor::kLoop) ||
      !r->pod(&s->anchored_at) || !std::isfinite(s->anchored_at) || !r->flag(&s->relocalised) ||
      !r->flag(&s->reported_new))
    return false;
  s->anchored_by = static_cast<SessionAnchor>(by);
  return r->pod(&s->submaps_accepted) && r->pod(&s->highest_seq) &&
         r->pod(&s->lowest_seq) && r->pod(&s->keyframes) && r->pod(&s->first_time) &&
         r->pod(&s->last_time) && std::isfinite(s->first_time) && std::isfinite(s->last_time);
}

void saveAgent(ByteWriter* w, const AgentStats& a) {
  w->pod(a.robot);
  w->pod(a.uuid);
  w->text(a.name);
  w->pod(a.current_session);
  w->pod(a.current_session_since);
  for (std::uint64_t v : {a.submaps_received, a.submaps_accepted, a.submaps_applied,
                          a.submaps_duplicate, a.submaps_stale, a.submaps_missing,
                          a.bytes_received, a.bytes_accepted, a.keyframes, a.landmarks,
                          a.observations})
    w->pod(v);
  w->pod(a.first_time);
  w->pod(a.last_time);
  w->flag(a.anchored);
  w->pose(a.T_W_A);
  w->count(a.sessions.size());
  for (const auto& [id, s] : a.sessions) saveSession(w, id, s);
}

bool loadAgent(ByteReader* r, AgentStats* a) {
  std::uint64_t* counters[] = {&a->submaps_received, &a->submaps_accepted, &a->submaps_applied,
                               &a->submaps_duplicate, &a->submaps_stale,   &a->submaps_missing,
                               &a->bytes_received,    &a->bytes_accepted,  &a->keyframes,
                               &a->landmarks,         &a->observations};
  if (!r->pod(&a->robot) || !r->pod(&a->uuid) || !r->text(&a->name) ||
      !r->pod(&a->current_session) || !r->pod(&a->current_session_since) ||
      !std::isfinite(a->current_session_since))
    return false;
  for (std::uint64_t* c : counters)
    if (!r->pod(c)) return false;
  std::uint64_t sessions = 0;
  if (!r->pod(&a->first_time) || !r->pod(&a->last_time) || !std::isfinite(a->first_time) ||
      !std::isfinite(a->last_time) || !r->flag(&a->anchored) || !r->pose(&a->T_W_A) ||
      !r->count(&sessions, 52))
    return false;
  for (std::uint64_t i = 0; i < sessions; ++i) {
    std::uint32_t id = 0;
    SessionStats s;
    if (!loadSession(r, &id, &s) || !a->sessions.emplace(id, s).second) return false;
  }
  return true;
}

}  // namespace

void Bookkeeper::save(ByteWriter* w) const {
  w->count(agents_.size());
  for (const AgentStats& a : agents_) saveAgent(w, a);
  w->count(seqs_.size());
  for (const auto& [id, tracker] : seqs_) {
    w->pod(id.first);
    w->pod(id.second);
    w->count(tracker.seen.size());
    for (std::uint64_t seq : tracker.seen) w->pod(seq);
  }
  w->count(applied_.size());
  for (const auto& [robot, session, seq] : applied_) {
    w->pod(robot);
    w->pod(session);
    w->pod(seq);
  }
  w->flag(world_.has_value());
  w->pod(world_.value_or(0));
}

Status Bookkeeper::load(ByteReader* r) {
  if (!agents_.empty() || !seqs_.empty() || !applied_.empty() || world_)
    return Error{"bookkeeper: load into a bookkeeper that already holds agents"};
  std::uint64_t n = 0;
  if (!r->count(&n, 100)) return Error{"bookkeeper: bad agent count"};
  for (std::uint64_t i = 0; i < n; ++i) {
    AgentStats a;
    if (!loadAgent(r, &a)) return Error{"bookkeeper: agent " + std::to_string(i) + " damaged"};
    if (a.robot != i) return Error{"bookkeeper: agent " + std::to_string(i) + " holds robot id " +
                                   std::to_string(a.robot)};
    if (!robot_of_.emplace(a.uuid, a.robot).second)
      return Error{"bookkeeper: uuid " + toString(a.uuid) + " twice"};
    agents_.push_back(std::move(a));
  }
  if (!r->count(&n, 16)) return Error{"bookkeeper: bad sequence table count"};
  for (std::uint64_t i = 0; i < n; ++i) {
    std::pair<RobotId, std::uint32_t> id;
    std::uint64_t seqs = 0;
    if (!r->pod(&id.first) || !r->pod(&id.second) || !r->count(&seqs, 8) ||
        id.first >= agents_.size() || seqs_.count(id))
      return Error{"bookkeeper: sequence table " + std::to_string(i) + " damaged"};
    SeqTracker& t = seqs_[id];
    for (std::uint64_t k = 0; k < seqs; ++k) {
      std::uint64_t seq = 0;
      if (!r->pod(&seq) || !t.seen.insert(seq).second)
        return Error{"bookkeeper: sequence table " + std::to_string(i) + " damaged"};
    }
  }
  if (!r->count(&n, 16)) return Error{"bookkeeper: bad applied count"};
  for (std::uint64_t i = 0; i < n; ++i) {
    RobotId robot = 0;
    std::uint32_t session = 0;
    std::uint64_t seq = 0;
    if (!r->pod(&robot) || !r->pod(&session) || !r->pod(&seq))
      return Error{"bookkeeper: applied entry " + std::to_string(i) + " damaged"};
    if (!isDuplicate(robot, session, seq))
      return Error{"bookkeeper: applied entry " + std::to_string(i) + " was never accepted"};
    applied_.insert({robot, session, seq});
  }
  bool has_world = false;
  RobotId world = 0;
  if (!r->flag(&has_world) || !r->pod(&world) || (has_world && world >= agents_.size()))
    return Error{"bookkeeper: world agent damaged"};
  if (has_world) world_ = world;
  return Status::Ok();
}

}  // namespace hermes
