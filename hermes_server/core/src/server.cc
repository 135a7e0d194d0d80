#include "hermes/server/server.h"

#include "hermes/core/frame_auth.h"

#include <algorithm>
#include <chrono>

namespace hermes {
namespace server {

Status ServerParams::read(const Config& config, const std::string& prefix) {
  if (Status s = bookkeeper.read(config, prefix + "bookkeeper."); !s) return s;
  if (Status s = config.get(prefix + "relocalisation_timeout_s", &bookkeeper.relocalisation_timeout_s); !s)
    return s;
  if (Status s = credibility.read(config, prefix); !s) return s;
  if (Status s = map.read(config, prefix); !s) return s;
  if (Status s = auth.read(config, prefix + "auth."); !s) return s;
  if (Status s = queue.read(config, prefix + "queue."); !s) return s;
  if (Status s = checkpoint.read(config, prefix); !s) return s;
  if (Status s = downlink.read(config, prefix + "downlink."); !s) return s;
  return validate();
}

void ServerParams::write(ConfigWriter& out, const std::string& prefix) const {
  bookkeeper.write(out, prefix + "bookkeeper.");
  out.set(prefix + "relocalisation_timeout_s", bookkeeper.relocalisation_timeout_s);
  credibility.write(out, prefix);
  map.write(out, prefix);
  auth.write(out, prefix + "auth.");
  queue.write(out, prefix + "queue.");
  checkpoint.write(out, prefix);
  downlink.write(out, prefix + "downlink.");
}

Status ServerParams::validate() const {
  for (Status s : {bookkeeper.validate(), credibility.validate(), map.validate(), auth.validate(),
                   queue.validate(), checkpoint.validate(), downlink.validate()})
    if (!s) return s;
  return Status::Ok();
}

Expected<std::unique_ptr<Server>> Server::create(const ServerParams& params,
                                                 const std::string& base_dir,
                                                 std::optional<Keyring> keyring) {
  if (Status s = params.validate(); !s) return Error{"server params: " + s.error()};
  if (!params.auth.enabled) {
    keyring.reset();
  } else if (!keyring) {
    auto loaded = Keyring::loadDir(expandHome(params.auth.key_dir));
    if (!loaded) return Error{"server: " + loaded.error()};
    keyring = std::move(*loaded);
  }
  auto vocabulary = loadVocabulary(params.map.place_recognition, base_dir);
  if (!vocabulary) return Error{"server: " + vocabulary.error()};
  if (params.checkpoint.enabled()) return resume(params, *vocabulary, std::move(keyring));
  ResumeReport report;
  auto server = startOnPrior(params, *vocabulary, keyring, &report);
  if (!server) return Error{server.error()};
  (*server)->resume_ = std::move(report);
  return server;
}

Server::Server(const ServerParams& params, std::shared_ptr<const Vocabulary> vocabulary,
               std::optional<Keyring> keyring)
    : params_(params),
      keyring_(std::move(keyring)),
      quotas_(params.queue),
      bookkeeper_(params.bookkeeper),
      queue_(params.credibility),
      map_(std::move(vocabulary), params.map, &bookkeeper_),
      receiver_(&bookkeeper_, [this](ReceivedSubmap&& r) {
        PendingSubmap p;
        p.agent = r.robot;
        p.session = r.submap.header.session;
        p.seq = r.submap.header.seq;
        p.arrival = r.arrival_time;
        p.handle = next_handle_++;
        quotas_.hold(r.robot, r.bytes);
        Pending& stored = stored_[p.handle];
        stored.submap = std::move(r);
        if (receiving_) stored.frame.assign(receiving_, receiving_ + receiving_size_);
        queue_.push(p);
      },
                DecodeLimits{},
                ReceiverGuards{keyring_ ? &*keyring_ : nullptr,
                               [this](RobotId robot, std::size_t bytes) {
                                 return quotas_.admit(robot, bytes);
                               }}),
      timings_(static_cast<std::size_t>(params.map.timing_window)) {
  HERMES_CHECK(params_.auth.enabled == keyring_.has_value(),
               "server: a keyring is needed exactly when server.auth.enabled");
  map_.setBookkeeperLock(&intake_mu_);
}

std::size_t Server::pending() const {
  std::lock_guard<std::mutex> lock(intake_mu_);
  return queue_.size();
}

ReceiveResult Server::onFrame(const std::uint8_t* data, std::size_t size,
                              const SubmapHeader* claimed, double now) {
  std::lock_guard<std::mutex> lock(intake_mu_);
  receiving_ = data;  // the sink keeps a copy of an accepted frame
  receiving_size_ = size;
  struct Clear {
    Server* s;
    ~Clear() { s->receiving_ = nullptr; }
  } clear{this};
  if (store_) return receiveJournaled(data, size, claimed, now);
  return receiver_.receive(data, size, claimed, now);
}

ReceiveResult Server::receiveJournaled(const std::uint8_t* data, std::size_t size,
                                       const SubmapHeader* claimed, double now) {
  auto peeked = peekFrame(data, size);
  const auto robot = peeked ? bookkeeper_.robotOf(peeked->routing.agent) : std::nullopt;
  if (!peeked ||
      (robot && bookkeeper_.isDuplicate(*robot, peeked->routing.session, peeked->routing.seq)))
    return receiver_.receive(data, size, claimed, now);  // rejected, or only acknowledged again
  // Nothing unauthenticated reaches the disk: the receiver refuses it with its reason.
  if (keyring_) {
    const Keyring::Entry* key = keyring_->find(peeked->routing.agent);
    if (!key || verifyFrameTag(data, size, key->key) != TagCheck::kValid)
      return receiver_.receive(data, size, claimed, now);
  }
  // Durably queued before acknowledged (DESIGN.md §9).
  const SubmapHeader& routing = peeked->routing;
  if (Status s = store_->journalPut(routing, now, data, size); !s) {
    ++durability_.journal_errors;
    durability_.last_error = s.error();
    ReceiveResult r;
    r.routing = routing;
    r.reason = "not acknowledged: " + s.error();
    return r;
  }
  ReceiveResult r = receiver_.receive(data, size, claimed, now);
  if (r.verdict == ArrivalVerdict::kAccept)
    journaled_.push_back(routing);
  else
    store_->journalRemove(routing);
  return r;
}

bool Server::takeNext(double now, std::optional<ReceivedSubmap>* next) {
  std::lock_guard<std::mutex> lock(intake_mu_);
  next->reset();
  if (queue_.empty()) return false;
  queue_.updateFrom(bookkeeper_, [this](RobotId r) { return map_.hasLoops(r); });
  const auto record = queue_.pop(now);
  if (!record) return false;
  auto it = stored_.find(record->item.handle);
  if (it == stored_.end()) return true;
  *next = std::move(it->second.submap);
  stored_.erase(it);
  quotas_.release((*next)->robot, (*next)->bytes);
  return true;
}

namespace {

/// Runs `f`; an exception (a bug: a solver or a container fed a case nobody
/// foresaw) becomes an error naming `what`, counted as a merge error, and the
/// server goes on serving every robot instead of dying with the map in memory.
template <typename F>
auto guarded(const std::string& what, F&& f) -> decltype(f()) {
  try {
    return f();
  } catch (const std::exception& e) {
    return Error{what + " threw " + e.what()};
  }
}

}  // namespace

int Server::process(double now, int max_submaps) {
  int merged = 0, popped = 0;
  // Called while the map manager anchors, which holds the intake lock then.
  const auto credibility = [this](RobotId r) { return queue_.score(r).c; };
  std::optional<ReceivedSubmap> next;
  bool drained = false;  // no submap waits any more
  while (max_submaps < 0 || merged < max_submaps) {
    const auto t0 = std::chrono::steady_clock::now();
    if (!takeNext(now, &next)) {
      drained = true;
      break;
    }
    if (!next) continue;
    const ReceivedSubmap& r = *next;
    map_.setClosureBudget(closureBudget(r.robot, now));
    last_merge_s_[r.robot] = now;
    auto stats = guarded("merge of robot " + std::to_string(r.robot) + " session " +
                             std::to_string(r.submap.header.session) + " seq " + std::to_string(r.submap.header.seq),
                         [&] { return map_.merge(r.robot, r.submap, credibility); });  // without the intake lock
    if (!stats) {
      ++counters_.merge_errors;
      counters_.last_error = stats.error();
    } else {
      ++counters_.merged;
      ++merged;
      counters_.keyframes_extended += static_cast<std::size_t>(stats->keyframes_extended);
      counters_.extensions_unknown += static_cast<std::size_t>(stats->extensions_unknown);
      counters_.loops_reverified += static_cast<std::size_t>(stats->loops_reverified);
      counters_.loops_reverify_deferred += static_cast<std::size_t>(stats->loops_reverify_deferred);
      noteSlowMerge({now, r.robot, r.submap.header.seq, stats->keyframes, stats->loops_attempted,
                     stats->stage_ms});
    }
    {
      std::lock_guard<std::mutex> lock(intake_mu_);
      (void)bookkeeper_.markApplied(r.robot, r.submap.header.session, r.submap.header.seq);
    }
    timings_.add("submap", std::chrono::duration<double, std::milli>(
                               std::chrono::steady_clock::now() - t0)
                               .count());
    ++popped;
  }
  // Closures the merges' budget deferred, one budget's worth while no submap
  // waits (closure_budget.h): a submap never waits behind them.
  if (drained && !full_solves_external_ && map_.fullSolveDue()) {
    solveFullInline();
  } else if (drained && map_.deferredClosures() > 0) {
    // A slice as large as a merge's budget; once the swarm has shrunk below the
    // share, as large as the largest share (a submap arriving meanwhile waits
    // for one slice, never for all that is left).
    const MapManagerParams& p = params_.map;
    const int largest_share = (p.closure_budget_swarm + p.closure_budget_min_robots - 1) / p.closure_budget_min_robots;
    int slice = map_.closureBudget() > 0 ? map_.closureBudget() : largest_share;
    if (slice <= 0) slice = static_cast<int>(map_.deferredClosures());  // no budget of any kind: all
    MergeStats stats;
    auto closed = guarded("deferred loop closures",
                          [&] { return map_.closeDeferred(slice, credibility, &stats); });
    counters_.loops_reverified += static_cast<std::size_t>(stats.loops_reverified);
    if (!closed) {
      ++counters_.merge_errors;
      counters_.last_error = closed.error();
    }
  }
  (void)bookkeeper_.checkRelocalisation(now);
  if (popped > 0 && store_ && now - last_checkpoint_ >= params_.checkpoint.period_s)
    (void)checkpoint(now);  // counted and kept in durability(); the journal still holds everything
  return merged;
}

int Server::closureBudget(RobotId robot, double now) const {
  const MapManagerParams& p = params_.map;
  if (p.closure_budget > 0 || p.closure_budget_swarm <= 0) return p.closure_budget;
  int active = 1;  // the merging robot
  for (const auto& [r, t] : last_merge_s_)
    if (r != robot && now - t <= p.active_robot_s) ++active;
  if (active < p.closure_budget_min_robots) return 0;
  return (p.closure_budget_swarm + active - 1) / active;
}

void Server::solveFullInline() {
  Expected<FullSolve> job = prepareFullSolve();
  if (!job) return;
  job->run();
  applyFullSolve(*job);
}

Expected<FullSolve> Server::prepareFullSolve() {
  Expected<FullSolve> job = guarded("full pose-graph solve", [&] { return map_.prepareFullSolve(); });
  if (!job) fullSolveFailed(job.error());
  return job;
}

void Server::applyFullSolve(const FullSolve& job) {
  Status applied = guarded("full pose-graph solve", [&] { return map_.applyFullSolve(job); });
  if (!applied) fullSolveFailed(applied.error());
}

void Server::fullSolveFailed(const std::string& error) {
  map_.postponeFullSolve();
  ++counters_.merge_errors;
  counters_.last_error = error;
}

void Server::noteSlowMerge(MergeBreakdown m) {
  const auto total = [](const MergeBreakdown& b) {
    auto it = b.stage_ms.find("total");
    return it == b.stage_ms.end() ? 0.0 : it->second;
  };
  if (slowest_.size() >= kSlowestMerges && total(m) <= total(slowest_.back())) return;
  auto at = std::find_if(slowest_.begin(), slowest_.end(),
                         [&](const MergeBreakdown& b) { return total(m) > total(b); });
  slowest_.insert(at, std::move(m));
  if (slowest_.size() > kSlowestMerges) slowest_.pop_back();
}

TimingStats Server::timings() const {
  TimingStats t = map_.timings();
  t.merge(timings_);
  return t;
}

Status Server::checkpoint(double now) {
  if (!store_) return Status::Ok();
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<SubmapHeader> covers;
  const std::vector<std::uint8_t> body = encodeState(&covers);
  // Outside the intake lock: only this thread writes checkpoint files, and the
  // journal (written meanwhile by onFrame) lives in other files.
  auto written = store_->write(body);
  std::lock_guard<std::mutex> lock(intake_mu_);
  if (!written) {
    ++durability_.checkpoint_errors;
    durability_.last_error = written.error();
    journaled_.insert(journaled_.begin(), covers.begin(), covers.end());  // not covered after all
    return Error{written.error()};
  }
  // Everything accepted until the state was copied is in this checkpoint
  // (merged or pending). A journal entry goes once the oldest checkpoint kept
  // covers it too: falling back to that one still finds everything accepted after it.
  covered_.push_back(std::move(covers));
  while (covered_.size() > static_cast<std::size_t>(params_.checkpoint.keep - 1)) {
    for (const SubmapHeader& h : covered_.front()) store_->journalRemove(h);
    covered_.pop_front();
  }
  last_checkpoint_ = now;
  ++durability_.checkpoints;
  durability_.last_checkpoint_bytes = body.size();
  timings_.add("checkpoint", std::chrono::duration<double, std::milli>(
                                 std::chrono::steady_clock::now() - t0)
                                 .count());
  return Status::Ok();
}

}  // namespace server
}  // namespace hermes
