#include "hermes/server/server.h"

#include <chrono>

namespace hermes {
namespace server {

Status ServerParams::read(const Config& config, const std::string& prefix) {
  if (Status s = bookkeeper.read(config, prefix + "bookkeeper."); !s) return s;
  if (Status s = credibility.read(config, prefix); !s) return s;
  if (Status s = map.read(config, prefix); !s) return s;
  if (Status s = auth.read(config, prefix + "auth."); !s) return s;
  if (Status s = queue.read(config, prefix + "queue."); !s) return s;
  return validate();
}

void ServerParams::write(ConfigWriter& out, const std::string& prefix) const {
  bookkeeper.write(out, prefix + "bookkeeper.");
  credibility.write(out, prefix);
  map.write(out, prefix);
  auth.write(out, prefix + "auth.");
  queue.write(out, prefix + "queue.");
}

Status ServerParams::validate() const {
  for (Status s : {bookkeeper.validate(), credibility.validate(), map.validate(), auth.validate(),
                   queue.validate()})
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
  return std::make_unique<Server>(params, *vocabulary, std::move(keyring));
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
        stored_.emplace(p.handle, std::move(r));
        queue_.push(p);
      },
                DecodeLimits{},
                ReceiverGuards{keyring_ ? &*keyring_ : nullptr,
                               [this](RobotId robot, std::size_t bytes) {
                                 return quotas_.admit(robot, bytes);
                               }}) {
  HERMES_CHECK(params_.auth.enabled == keyring_.has_value(),
               "server: a keyring is needed exactly when server.auth.enabled");
}

ReceiveResult Server::onFrame(const std::uint8_t* data, std::size_t size,
                              const SubmapHeader* claimed, double now) {
  return receiver_.receive(data, size, claimed, now);
}

int Server::process(double now, int max_submaps) {
  int merged = 0;
  const auto credibility = [this](RobotId r) { return queue_.score(r).c; };
  while (!queue_.empty() && (max_submaps < 0 || merged < max_submaps)) {
    const auto t0 = std::chrono::steady_clock::now();
    queue_.updateFrom(bookkeeper_, [this](RobotId r) { return map_.hasLoops(r); });
    const auto record = queue_.pop(now);
    if (!record) break;
    auto it = stored_.find(record->item.handle);
    if (it == stored_.end()) continue;
    ReceivedSubmap r = std::move(it->second);
    stored_.erase(it);
    quotas_.release(r.robot, r.bytes);
    auto stats = map_.merge(r.robot, r.submap, credibility);
    if (!stats) {
      ++counters_.merge_errors;
      counters_.last_error = stats.error();
    } else {
      ++counters_.merged;
      ++merged;
      counters_.keyframes_extended += static_cast<std::size_t>(stats->keyframes_extended);
      counters_.extensions_unknown += static_cast<std::size_t>(stats->extensions_unknown);
      counters_.loops_reverified += static_cast<std::size_t>(stats->loops_reverified);
    }
    (void)bookkeeper_.markApplied(r.robot, r.submap.header.session, r.submap.header.seq);
    timings_.add("submap", std::chrono::duration<double, std::milli>(
                               std::chrono::steady_clock::now() - t0)
                               .count());
  }
  return merged;
}

TimingStats Server::timings() const {
  TimingStats t = map_.timings();
  t.merge(timings_);
  return t;
}

}  // namespace server
}  // namespace hermes
