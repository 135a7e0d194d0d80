// The server's state as a checkpoint body, and resuming from the checkpoint
// directory (checkpoint_store.h). Body, in order:
//   bookkeeper (bookkeeper_io.cc), merge queue (credibility.cc),
//   map manager (map_manager_io.cc: global map, odometry chain, place database
//   order, loop ids, world, solve counters, timings),
//   pending submaps: count x { handle u64, robot u32, bytes u64, arrival f64,
//                              frame as received (wire format, decoded again) },
//   next handle, server counters, receiver counters, server timings,
//   durability counters.
// A prior map (server.h) is such a body, read from another directory.
#include <chrono>

#include "hermes/server/byte_codec.h"
#include "hermes/server/server.h"

namespace hermes {
namespace server {
namespace {

void saveCounters(ByteWriter* w, const ServerCounters& c, const ReceiverStats& r,
                  const DurabilityStats& d) {
  for (std::size_t v : {c.merged, c.merge_errors, c.keyframes_extended, c.extensions_unknown,
                        c.loops_reverified, c.loops_reverify_deferred})
    w->count(v);
  w->text(c.last_error);
  for (std::size_t v : {r.frames, r.accepted, r.duplicates, r.stale, r.rejected, r.bytes})
    w->count(v);
  for (std::size_t v : {d.checkpoints, d.checkpoint_errors, d.last_checkpoint_bytes,
                        d.journal_errors, d.resumes, d.journal_replayed, d.refused_files})
    w->count(v);
  w->text(d.last_error);
}

bool loadCounters(ByteReader* r, ServerCounters* c, ReceiverStats* rs, DurabilityStats* d) {
  auto all = [r](std::initializer_list<std::size_t*> values) {
    for (std::size_t* v : values) {
      std::uint64_t x = 0;
      if (!r->pod(&x)) return false;
      *v = static_cast<std::size_t>(x);
    }
    return true;
  };
  return all({&c->merged, &c->merge_errors, &c->keyframes_extended, &c->extensions_unknown,
              &c->loops_reverified, &c->loops_reverify_deferred}) &&
         r->text(&c->last_error) &&
         all({&rs->frames, &rs->accepted, &rs->duplicates, &rs->stale, &rs->rejected, &rs->bytes}) &&
         all({&d->checkpoints, &d->checkpoint_errors, &d->last_checkpoint_bytes, &d->journal_errors,
              &d->resumes, &d->journal_replayed, &d->refused_files}) &&
         r->text(&d->last_error);
}

}  // namespace

void Server::saveIntake(ByteWriter* head, ByteWriter* tail) const {
  bookkeeper_.save(head);
  queue_.save(head);
  // (the map goes here)
  tail->count(stored_.size());
  for (const auto& [handle, p] : stored_) {
    tail->pod(handle);
    tail->pod(p.submap.robot);
    tail->count(p.submap.bytes);
    tail->pod(p.submap.arrival_time);
    tail->blob(p.frame);
  }
  tail->pod(next_handle_);
  saveCounters(tail, counters_, receiver_.stats(), durability_);
  saveTimings(tail, timings_);
}

std::vector<std::uint8_t> Server::encodeState(std::vector<SubmapHeader>* covers) {
  ByteWriter w, tail;
  {
    std::lock_guard<std::mutex> lock(intake_mu_);
    saveIntake(&w, &tail);
    covers->swap(journaled_);
  }
  return withMap(std::move(w), tail);
}

std::vector<std::uint8_t> Server::saveState() const {
  ByteWriter w, tail;
  {
    std::lock_guard<std::mutex> lock(intake_mu_);
    saveIntake(&w, &tail);
  }
  return withMap(std::move(w), tail);
}

std::vector<std::uint8_t> Server::withMap(ByteWriter head, const ByteWriter& tail) const {
  map_.save(&head);
  head.out.insert(head.out.end(), tail.out.begin(), tail.out.end());
  return std::move(head.out);
}

Status Server::loadState(const std::vector<std::uint8_t>& body) {
  if (!stored_.empty() || !queue_.empty() || !bookkeeper_.robots().empty())
    return Error{"load into a server that has already received submaps"};
  ByteReader r(body.data(), body.size());
  if (Status s = bookkeeper_.load(&r); !s) return s;
  if (!queue_.load(&r)) return Error{"merge queue damaged"};
  if (Status s = map_.load(&r); !s) return s;
  std::uint64_t n = 0;
  if (!r.count(&n, 36)) return Error{"bad pending submap count"};
  for (std::uint64_t i = 0; i < n; ++i) {
    std::uint64_t handle = 0, bytes = 0;
    Pending p;
    if (!r.pod(&handle) || !r.pod(&p.submap.robot) || !r.pod(&bytes) ||
        !r.pod(&p.submap.arrival_time) || !r.blob(&p.frame))
      return Error{"pending submap " + std::to_string(i) + " truncated"};
    auto submap = decodeSubmap(p.frame);
    if (!submap) return Error{"pending submap " + std::to_string(i) + ": " + submap.error()};
    p.submap.submap = std::move(*submap);
    p.submap.bytes = static_cast<std::size_t>(bytes);
    const SubmapHeader& h = p.submap.submap.header;
    if (!bookkeeper_.isDuplicate(p.submap.robot, h.session, h.seq))
      return Error{"pending submap " + std::to_string(i) + " was never accepted"};
    const RobotId robot = p.submap.robot;
    if (!stored_.emplace(handle, std::move(p)).second)
      return Error{"pending submap handle " + std::to_string(handle) + " twice"};
    quotas_.hold(robot, static_cast<std::size_t>(bytes));  // released when merged
  }
  const std::vector<PendingSubmap> queued = queue_.pending();
  if (queued.size() != stored_.size())
    return Error{"merge queue and pending submaps disagree"};
  for (const PendingSubmap& q : queued) {
    auto it = stored_.find(q.handle);
    if (it == stored_.end() || it->second.submap.robot != q.agent ||
        it->second.submap.submap.header.seq != q.seq ||
        it->second.submap.submap.header.session != q.session)
      return Error{"merge queue names a pending submap the checkpoint does not hold"};
  }
  ReceiverStats receiver;
  if (!r.pod(&next_handle_) || !loadCounters(&r, &counters_, &receiver, &durability_))
    return Error{"counters damaged"};
  if (!stored_.empty() && stored_.rbegin()->first >= next_handle_)
    return Error{"pending submap handle beyond the next handle"};
  if (!loadTimings(&r, &timings_)) return Error{"timings damaged"};
  if (!r.atEnd()) return Error{"trailing bytes after the state"};
  receiver_.restoreStats(receiver);
  ++durability_.checkpoints;  // the body was encoded before its own write counted
  return Status::Ok();
}

Expected<std::unique_ptr<Server>> Server::startOnPrior(const ServerParams& params,
                                                       std::shared_ptr<const Vocabulary> vocabulary,
                                                       const std::optional<Keyring>& keyring,
                                                       ResumeReport* report) {
  const std::string& dir = params.checkpoint.prior_map;
  if (dir.empty()) return std::make_unique<Server>(params, vocabulary, keyring);
  std::string why;
  const std::vector<std::string> files = CheckpointStore::listCheckpoints(dir);
  if (files.empty()) why = "\n  it holds no server checkpoint (checkpoint-*.hck)";
  for (const std::string& file : files) {  // newest first; nothing in the directory is changed
    auto candidate = std::make_unique<Server>(params, vocabulary, keyring);
    auto body = CheckpointStore::readCheckpoint(file);
    Status s = body ? candidate->loadState(*body) : Status(Error{body.error()});
    if (s) {
      candidate->sealPrior();
      report->prior_map = file;
      if (!why.empty()) report->problems.push_back("server prior map: newer checkpoints refused:" + why);
      return candidate;
    }
    why += "\n  " + file + ": " + s.error();
  }
  const std::string what = "server: prior map '" + dir + "' cannot be used:" + why;
  if (!params.checkpoint.prior_map_optional)
    return Error{what + "\n(server.prior_map_optional: true starts with an empty map instead)"};
  report->problems.push_back(what + "\nstarting with an empty map (server.prior_map_optional)");
  return std::make_unique<Server>(params, vocabulary, keyring);
}

void Server::sealPrior() {
  map_.renameAgents(bookkeeper_.sealAsPrior());
  // This mission's counts start at zero; the prior's map and world stay.
  counters_ = ServerCounters{};
  durability_ = DurabilityStats{};
  receiver_.restoreStats(ReceiverStats{});
}

Expected<std::unique_ptr<Server>> Server::resume(const ServerParams& params,
                                                 std::shared_ptr<const Vocabulary> vocabulary,
                                                 const std::optional<Keyring>& keyring) {
  const auto t0 = std::chrono::steady_clock::now();
  auto store = CheckpointStore::open(params.checkpoint);
  if (!store) return Error{store.error()};
  ResumeReport report;
  std::unique_ptr<Server> server;
  const std::vector<std::string> files = store->checkpoints();
  for (const std::string& file : files) {
    auto candidate = std::make_unique<Server>(params, vocabulary, keyring);
    auto body = CheckpointStore::readCheckpoint(file);
    Status s = body ? candidate->loadState(*body) : Status(Error{body.error()});
    if (s) {
      server = std::move(candidate);
      report.checkpoint = file;
      break;
    }
    report.problems.push_back("server checkpoint " + file + " refused: " + s.error());
    CheckpointStore::refuse(file);
  }
  if (!files.empty() && !server) {
    std::string why;
    for (const std::string& p : report.problems) why += "\n  " + p;
    return Error{"server: no usable checkpoint in " + params.checkpoint.dir +
                 " (move the directory away to start with an empty map):" + why};
  }
  if (!server) {  // nothing of this mission yet: on the prior map, if there is one
    auto fresh = startOnPrior(params, vocabulary, keyring, &report);
    if (!fresh) return Error{fresh.error()};
    server = std::move(*fresh);
  }
  server->store_ = std::move(*store);
  // Accepted (and acknowledged) after that checkpoint: queue them again.
  std::vector<SubmapHeader> covered;
  for (JournalEntry& e : server->store_->journal(&report.problems)) {
    auto head = peekFrame(e.frame.data(), e.frame.size());
    const auto robot = head ? server->bookkeeper_.robotOf(head->routing.agent) : std::nullopt;
    if (head && robot &&
        server->bookkeeper_.isDuplicate(*robot, head->routing.session, head->routing.seq)) {
      covered.push_back(head->routing);  // the checkpoint covers it; kept for a fallback
      ++report.journal_covered;
      continue;
    }
    server->receiving_ = e.frame.data();
    server->receiving_size_ = e.frame.size();
    const ReceiveResult r = server->receiver_.receive(e.frame.data(), e.frame.size(), nullptr, e.arrival);
    server->receiving_ = nullptr;
    if (r.verdict == ArrivalVerdict::kAccept) {
      server->journaled_.push_back(r.routing);
      ++report.journal_replayed;
    } else {
      report.problems.push_back("server journal entry " + e.file + " refused: " +
                                toString(r.verdict) + ": " + r.reason);
      CheckpointStore::refuse(e.file);
    }
  }
  server->covered_.push_back(std::move(covered));
  report.resumed = !report.checkpoint.empty() || report.journal_replayed > 0;
  report.load_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  DurabilityStats& d = server->durability_;
  if (report.resumed) ++d.resumes;
  d.journal_replayed += report.journal_replayed;
  d.refused_files += report.problems.size();
  server->resume_ = std::move(report);
  return server;
}

}  // namespace server
}  // namespace hermes
