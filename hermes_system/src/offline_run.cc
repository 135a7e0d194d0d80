#include "hermes/system/offline_run.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <thread>

#include <unistd.h>

#include "hermes/agent/dataset_feed.h"
#include "hermes/server/server_outputs.h"
#include "hermes/system/tracking_record.h"

namespace hermes::system {
namespace {

/// Resident memory of this process [B] (/proc/self/statm; 0 where it is absent).
std::size_t residentBytes() {
  std::ifstream f("/proc/self/statm");
  std::size_t pages = 0, resident = 0;
  if (!(f >> pages >> resident)) return 0;
  return resident * static_cast<std::size_t>(::sysconf(_SC_PAGESIZE));
}

}  // namespace

namespace fs = std::filesystem;

OfflineRun::OfflineRun(SystemParams params, std::unique_ptr<server::Server> server)
    : params_(std::move(params)), server_(std::move(server)) {}

Expected<std::unique_ptr<OfflineRun>> OfflineRun::create(const SystemParams& params,
                                                         std::vector<AgentSource> agents,
                                                         const std::string& spool_root,
                                                         const std::string& base_dir) {
  if (Status s = params.validate(); !s) return Error{s.error()};
  if (agents.empty()) return Error{"no agent to run"};
  auto trace = params.link.makeTrace();
  if (!trace.ok()) return Error{trace.error()};
  std::unique_ptr<OfflineRun> run(new OfflineRun(params, nullptr));
  run->base_dir_ = base_dir;
  run->spool_root_ = spool_root;
  if (!params.clock.server_restart_at.empty() && !run->params_.server.checkpoint.enabled())
    run->params_.server.checkpoint.dir =
        (fs::path(spool_root).parent_path() / "server_checkpoint").string();
  if (run->params_.server.checkpoint.enabled()) {  // a run starts fresh
    std::error_code ec;
    fs::remove_all(run->params_.server.checkpoint.dir, ec);
    if (ec)
      return Error{"cannot empty the server checkpoint directory " +
                   run->params_.server.checkpoint.dir + ": " + ec.message()};
  }
  auto server = server::Server::create(run->params_.server, base_dir);
  if (!server.ok()) return Error{server.error()};
  run->server_ = std::move(*server);
  std::sort(run->params_.clock.server_restart_at.begin(), run->params_.clock.server_restart_at.end());
  run->link_ = std::make_unique<SharedLink>(*trace, static_cast<int>(agents.size()),
                                            static_cast<std::uint64_t>(params.link.seed),
                                            static_cast<std::size_t>(params.link.packet_bytes));
  if (params.link.scenario.empty() && run->params_.server.downlink.enabled)
    run->downlink_ = std::make_unique<DownlinkChannel>(
        run->params_.server.downlink, *trace, static_cast<int>(agents.size()),
        static_cast<std::uint64_t>(params.link.seed) ^ 0x9e3779b97f4a7c15ull,
        static_cast<std::size_t>(params.link.packet_bytes));
  run->last_transmitted_.assign(agents.size(), 0);
  for (std::size_t i = 0; i < agents.size(); ++i) {
    AgentSource& src = agents[i];
    if (!src.dataset) return Error{"agent " + src.name + ": no dataset"};
    if (src.name.empty() || src.name.find_first_of(",\n") != std::string::npos)
      return Error{"agent name '" + src.name + "' is empty or holds a comma/newline"};
    for (std::size_t j = 0; j < i; ++j)
      if (agents[j].name == src.name) return Error{"two agents are named " + src.name};
    const DatasetInfo& info = src.dataset->info();
    if (info.frame_count == 0) return Error{"agent " + src.name + ": the dataset holds no frames"};
    OfflineAgent a;
    a.name = src.name;
    a.frames = src.max_frames > 0 ? std::min(src.max_frames, info.frame_count) : info.frame_count;
    if (!src.sorties.empty()) {
      if (src.sorties[0].first_frame != 0) return Error{"agent " + src.name + ": its first sortie must start at frame 0"};
      for (std::size_t k = 1; k < src.sorties.size(); ++k)
        if (src.sorties[k].first_frame <= src.sorties[k - 1].first_frame || src.sorties[k].first_frame >= a.frames)
          return Error{"agent " + src.name + ": sortie " + std::to_string(k) + " starts at frame " +
                       std::to_string(src.sorties[k].first_frame) + ", not after the one before and before frame " +
                       std::to_string(a.frames)};
      a.sorties = std::move(src.sorties);
    }
    if (src.clock_origin) {
      a.clock_offset = *src.clock_origin;
    } else if (!a.sorties.empty() ||
               trackingMode(params, src.name, *src.dataset, a.frames) == TrackingMode::kReplay) {
      a.clock_offset = src.dataset->frameTime(0);  // the stamp frame 0 carries; no image
    } else {
      auto first = loadCameraFrame(*src.dataset, 0);
      if (!first.ok()) return Error{"agent " + src.name + ": frame 0: " + first.error()};
      a.clock_offset = first->stamp;
    }
    a.dataset = std::move(src.dataset);
    run->agents_.push_back(std::move(a));
    auto pipeline = run->makePipeline(i, /*fresh=*/true);
    if (!pipeline) return Error{pipeline.error()};
    run->agents_[i].pipeline = std::move(*pipeline);
    const OfflineAgent& made = run->agents_[i];
    if (!made.sorties.empty()) {
      if (Status s = run->setUpSortie(i, 0); !s) return Error{s.error()};
    } else if (Status s = setUpTrackingRecord(run->params_, made.name, *made.dataset, made.frames,
                                              made.pipeline.get());
               !s) {
      return Error{s.error()};
    }
  }
  if (Status s = run->checkResets(); !s) return Error{s.error()};
  if (params.corrupt.active() &&
      std::none_of(run->agents_.begin(), run->agents_.end(),
                   [&](const OfflineAgent& a) { return a.name == params.corrupt.agent; }))
    return Error{"corrupt.agent '" + params.corrupt.agent + "' names no agent of this run"};
  if (!params.link.scenario.empty())
    if (Status s = run->createNetwork(spool_root); !s) return Error{s.error()};
  return run;
}

Expected<std::unique_ptr<agent::AgentPipeline>> OfflineRun::makePipeline(std::size_t i, bool fresh) {
  const OfflineAgent& a = agents_[i];
  const DatasetInfo& info = a.dataset->info();
  agent::AgentPipelineParams ap = params_.offlineAgent();  // deterministic solver limits
  ap.uplink.buffer.dir = (fs::path(spool_root_) / a.name).string();
  if (fresh) {
    std::error_code ec;
    fs::remove_all(ap.uplink.buffer.dir, ec);  // a run starts with an empty spool
  }
  auto pipeline = agent::AgentPipeline::create(ap, a.name, agent::AgentCamera{info.K, info.baseline, info.T_B_C});
  if (!pipeline.ok()) return Error{pipeline.error()};
  if (params_.corrupt.active() && params_.corrupt.agent == a.name)
    (*pipeline)->setOdometryCorruption(params_.corrupt);
  Status s = (*pipeline)->attachUplink(
      [this, i](std::uint32_t session, std::uint64_t seq, const std::vector<std::uint8_t>& frame) {
        OfflineAgent& sender = agents_[i];
        if (holding_)
          sender.held.push_back({sender.feeding_stamp, session, seq, frame});
        else
          transmit(i, session, seq, frame);
      },
      a.clock_offset);
  if (!s) return Error{s.error()};
  return std::move(*pipeline);
}

Status OfflineRun::checkResets() {
  resets_ = params_.clock.agent_reset;
  std::stable_sort(resets_.begin(), resets_.end(),
                   [](const AgentReset& a, const AgentReset& b) { return a.at_s < b.at_s; });
  for (const AgentReset& r : resets_) {
    auto it = std::find_if(agents_.begin(), agents_.end(),
                           [&](const OfflineAgent& a) { return a.name == r.agent; });
    const std::string what = "system.agent_reset '" + formatAgentResets({r}) + "'";
    if (it == agents_.end()) return Error{what + " names no agent of this run"};
    const double last = it->dataset->frameTime(it->frames - 1) - it->clock_offset;
    if (r.at_s > last)
      return Error{what + ": after the agent's last frame (" + std::to_string(last) + " s)"};
  }
  return Status::Ok();
}

Status OfflineRun::resetAgents(double t) {
  for (; next_reset_ < resets_.size() && t + 1e-9 >= resets_[next_reset_].at_s; ++next_reset_) {
    const AgentReset& reset = resets_[next_reset_];
    const std::size_t i = static_cast<std::size_t>(
        std::find_if(agents_.begin(), agents_.end(),
                     [&](const OfflineAgent& a) { return a.name == reset.agent; }) -
        agents_.begin());
    if (Status s = replacePipeline(i, t, /*takeoff=*/false); !s) return s;
  }
  return Status::Ok();
}

Status OfflineRun::replacePipeline(std::size_t i, double t, bool takeoff) {
  OfflineAgent& a = agents_[i];
  AgentResetRecord r;
  r.at_s = t;
  r.frame = a.next;
  r.takeoff = takeoff;
  r.old_session = a.pipeline->session();
  r.bytes_sent_before = static_cast<std::int64_t>(a.pipeline->uplink()->stats().bytes_sent);
  r.submaps_sent_before = a.pipeline->submapsSent();
  r.window_bytes_before = a.pipeline->windows().window_bytes;
  if (takeoff && a.pipeline->hasCarriedWindow()) ++a.windows_lost_landed;
  a.pipeline.reset();  // a crash: the open window and the map are gone, the spool stays
  auto pipeline = makePipeline(i, /*fresh=*/false);
  const std::string what = "agent " + a.name + (takeoff ? " take-off" : " reset") + " at " + std::to_string(t) + " s: ";
  if (!pipeline) return Error{what + pipeline.error()};
  a.pipeline = std::move(*pipeline);
  if (takeoff)
    if (Status s = setUpSortie(i, a.sortie); !s) return Error{what + s.error()};
  r.new_session = a.pipeline->session();
  for (const auto& [session, seq] : a.pipeline->uplink()->buffer().pendingKeys())
    r.spool_carried += session < r.new_session;
  a.resets.push_back(r);
  return Status::Ok();
}

std::size_t OfflineRun::sortieEnd(const OfflineAgent& a) {
  return a.sortie + 1 < a.sorties.size() ? a.sorties[a.sortie + 1].first_frame : a.frames;
}

Status OfflineRun::setUpSortie(std::size_t i, std::size_t s) {
  const OfflineAgent& a = agents_[i];
  const Sortie& sortie = a.sorties[s];
  if (sortie.replay_path.empty()) return Status::Ok();
  const std::string what = "agent " + a.name + " sortie " + std::to_string(s) + ": ";
  auto log = agent::readTrackingLog(sortie.replay_path);
  if (!log) return Error{what + log.error()};
  if (Status k = log->key.matches(sortie.replay_key); !k)
    return Error{what + sortie.replay_path + ": " + k.error()};
  shiftTrackingLog(&*log, sortie.replay_shift_s);
  // The frames' stamps as the dataset carries them (the shift rounds them).
  std::size_t f = sortie.first_frame;
  const std::size_t end = s + 1 < a.sorties.size() ? a.sorties[s + 1].first_frame : a.frames;
  for (agent::TrackingStep& step : log->steps) {
    if (step.flush) continue;
    if (f >= end) return Error{what + sortie.replay_path + " holds more frames than the sortie (" +
                               std::to_string(end - sortie.first_frame) + ")"};
    const double stamp = a.dataset->frameTime(f++);
    if (std::abs(stamp - step.stamp) > 1e-4)
      return Error{what + sortie.replay_path + ": frame " + std::to_string(f - 1) + " is at " +
                   std::to_string(stamp) + " s, the shifted recording at " + std::to_string(step.stamp) + " s"};
    step.stamp = stamp;
  }
  if (Status r = a.pipeline->replayTracking(std::move(*log)); !r) return Error{what + r.error()};
  return Status::Ok();
}

Status OfflineRun::createNetwork(const std::string& spool_root) {
  std::vector<std::string> names;
  for (const OfflineAgent& a : agents_) names.push_back(a.name);
  auto scenario = Scenario::fromFile(params_.link.scenario, names);
  if (!scenario) return Error{"link.scenario: " + scenario.error()};
  NetworkHooks hooks;
  hooks.to_server = [this](std::size_t i, std::uint32_t session, std::uint64_t seq,
                           const std::vector<std::uint8_t>& bytes, double arrival) {
    return receive(i, session, seq, bytes, arrival);
  };
  hooks.acked = [this](std::size_t i, std::uint32_t session, std::uint64_t seq, double t) {
    if (agents_[i].pipeline->onAck(session, seq, t)) ++agents_[i].acked;
  };
  hooks.handed_over = [this](std::size_t i, std::uint32_t session, std::uint64_t seq, double t) {
    (void)agents_[i].pipeline->onHandedOver(session, seq, t);
  };
  hooks.lost = [this](std::size_t i) { ++agents_[i].lost_messages; };
  auto net = RelayNetwork::create(std::move(*scenario), params_.relay, params_.run.agent.uplink,
                                  names, spool_root, static_cast<std::uint64_t>(params_.link.seed),
                                  static_cast<std::size_t>(params_.link.packet_bytes), std::move(hooks));
  if (!net) return Error{net.error()};
  network_ = std::move(*net);
  last_own_bytes_.assign(agents_.size(), 0.0);
  return Status::Ok();
}

std::size_t OfflineRun::lostMessages() const {
  std::size_t n = 0;
  for (const OfflineAgent& a : agents_) n += a.lost_messages;
  return n;
}

void OfflineRun::deliver(double t) {
  if (network_) {
    network_->deliver(t);
    return;
  }
  for (LinkDelivery& d : link_->advanceTo(t)) {
    auto it = messages_.find(d.message.id);
    if (it == messages_.end()) continue;
    const MessageKey key = it->second;
    messages_.erase(it);
    if (d.lost) {  // the sender's resend timeout brings it again
      ++agents_[key.agent].lost_messages;
      continue;
    }
    if (!receive(key.agent, key.session, key.seq, *d.message.payload, d.arrival_time)) continue;
    const double ack = link_->ackArrival(d.arrival_time);
    if (ack >= 0) acks_.push_back(PendingAck{ack, key.agent, key.session, key.seq});
  }
}

bool OfflineRun::receive(std::size_t i, std::uint32_t session, std::uint64_t seq,
                         const std::vector<std::uint8_t>& bytes, double arrival) {
  OfflineAgent& a = agents_[i];
  if (!server_) {  // restarting: nobody receives it, the agent resends it
    ++restarts_.back().frames_lost_down;
    return false;
  }
  SubmapHeader claimed;
  claimed.agent = a.pipeline->agentId();
  claimed.session = session;
  claimed.seq = seq;
  const ReceiveResult r = server_->onFrame(bytes.data(), bytes.size(), &claimed, arrival);
  if (r.verdict == ArrivalVerdict::kAccept || r.verdict == ArrivalVerdict::kDuplicate)
    a.robot = r.robot;
  if (r.verdict == ArrivalVerdict::kDuplicate) ++a.duplicates;
  if (r.verdict == ArrivalVerdict::kAccept && !restarts_.empty() &&
      restarts_.back().first_accept_s < 0)
    restarts_.back().first_accept_s = arrival;
  return r.acknowledge;
}

void OfflineRun::acknowledge(double t) {
  std::stable_sort(acks_.begin(), acks_.end(),
                   [](const PendingAck& a, const PendingAck& b) { return a.time < b.time; });
  std::size_t done = 0;
  for (; done < acks_.size() && acks_[done].time <= t; ++done) {
    const PendingAck& k = acks_[done];
    OfflineAgent& a = agents_[k.agent];
    if (a.pipeline->onAck(k.session, k.seq, t)) ++a.acked;
  }
  acks_.erase(acks_.begin(), acks_.begin() + static_cast<std::ptrdiff_t>(done));
  if (network_) network_->acknowledge(t);
  std::size_t g = 0;
  for (; g < globals_.size() && globals_[g].time <= t; ++g)
    agents_[globals_[g].agent].pipeline->onGlobalPose(globals_[g].update, t);
  globals_.erase(globals_.begin(), globals_.begin() + static_cast<std::ptrdiff_t>(g));
}

void OfflineRun::sendGlobalPoses(double t) {
  // Down the link with its latency; lost while the link is down. No loss draw:
  // the updates are tiny and repeated after every merge, and drawing would
  // change the submaps' losses against runs without them.
  const LinkState s = link_->trace().at(t);
  if (s.rate_mbitps <= 0) return;
  for (const auto& [robot, update] : server::globalPoseUpdates(server_->map()))
    for (std::size_t i = 0; i < agents_.size(); ++i)
      if (agents_[i].robot == robot) globals_.push_back({t + s.latency_ms * 1e-3, i, update});
}

void OfflineRun::sendDownlink(double t) {
  std::vector<server::DownlinkRecipient> recipients;
  std::vector<std::size_t> agent_of;
  for (std::size_t i = 0; i < agents_.size(); ++i) {
    const OfflineAgent& a = agents_[i];
    if (!a.robot || a.landed) continue;
    recipients.push_back({*a.robot, a.pipeline->agentId(), a.pipeline->session()});
    agent_of.push_back(i);
  }
  downlink_->send(server_->map(), recipients, agent_of, t);
}

void OfflineRun::receiveDownlink(double t) {
  downlink_->advance(t, server_ != nullptr,
                     [&](std::size_t i, const std::vector<std::uint8_t>& bytes) -> std::optional<MapDownAck> {
                       auto ack = agents_[i].pipeline->onMapDown(bytes.data(), bytes.size(), t);
                       if (!ack) return std::nullopt;
                       return *ack;
                     });
}

void OfflineRun::transmit(std::size_t i, std::uint32_t session, std::uint64_t seq,
                          const std::vector<std::uint8_t>& frame) {
  OfflineAgent& sender = agents_[i];
  if (!sender.sent.insert({session, seq}).second) ++sender.resent;
  if (network_) {
    network_->send(i, session, seq, frame, now_);
    return;
  }
  LinkMessage m;
  m.sender = static_cast<int>(i);
  m.id = next_message_++;
  m.bytes = frame.size();
  m.payload = std::make_shared<const std::vector<std::uint8_t>>(frame);
  m.send_time = now_;
  messages_[m.id] = MessageKey{i, session, seq};
  link_->send(std::move(m), now_);
}

Status OfflineRun::feedAgent(std::size_t i, double t) {
  OfflineAgent& a = agents_[i];
  while (a.next < a.frames) {
    const double ts = a.dataset->frameTime(a.next) - a.clock_offset;
    if (ts > t) break;
    if (a.landed) {  // the next sortie takes off: a new session with a fresh map
      ++a.sortie;
      a.landed = false;
      if (Status s = replacePipeline(i, ts, /*takeoff=*/true); !s) return s;
    }
    a.feeding_stamp = ts;
    const std::string what = "agent " + a.name + ": frame " + std::to_string(a.next) + ": ";
    double stamp = 0;
    if (a.pipeline->replaying()) {  // the recorded tracking of this frame, no image
      stamp = a.dataset->frameTime(a.next);
      if (auto r = a.pipeline->replayFrame(stamp); !r.ok()) return Error{what + r.error()};
    } else if (auto frame = loadCameraFrame(*a.dataset, a.next); !frame.ok()) {
      // A frame that cannot be read costs that frame: counted, logged once per cause.
      if (a.skips.add(frame.error()))
        std::fprintf(stderr, "hermes: warning: %sskipped (%s); further frames of this cause are counted\n",
                     what.c_str(), frame.error().c_str());
      stamp = -1;
    } else {
      stamp = frame->stamp;
      if (auto r = a.pipeline->feed(*frame); !r.ok()) return Error{what + r.error()};
    }
    const Trajectory& odo = a.pipeline->trajectory();
    if (stamp >= 0 && !odo.empty() && odo.back().t == stamp)
      if (const auto T_W_B = a.pipeline->globalPose().inWorld(odo.back().T_W_B))
        a.global_track.push_back({stamp, *T_W_B});
    if (++a.next == sortieEnd(a)) {  // the end of the data or a landing
      a.pipeline->flushWindow();  // the last, partial window
      if (Status s = a.pipeline->finishTracking(); !s) return s;  // recording / replay
      a.next_retry = t + params_.run.agent.tracker.window.period_s;
      a.landed = a.next < a.frames;
    }
  }
  return Status::Ok();
}

Status OfflineRun::feedDueFrames(double t) {
  std::vector<std::size_t> due;
  for (std::size_t i = 0; i < agents_.size(); ++i) {
    const OfflineAgent& a = agents_[i];
    if (a.next < a.frames && a.dataset->frameTime(a.next) - a.clock_offset <= t) due.push_back(i);
  }
  if (due.empty()) return Status::Ok();
  std::vector<Status> status(agents_.size(), Status::Ok());
  holding_ = true;
  const std::size_t threads =
      std::min<std::size_t>(std::max(1, params_.clock.agent_threads), due.size());
  std::atomic<std::size_t> next{0};
  auto work = [&] {
    for (std::size_t k; (k = next.fetch_add(1)) < due.size();) status[due[k]] = feedAgent(due[k], t);
  };
  std::vector<std::thread> workers;
  for (std::size_t w = 1; w < threads; ++w) workers.emplace_back(work);
  work();
  for (std::thread& w : workers) w.join();
  holding_ = false;
  // On the link in the order one thread feeding the earliest frame first sends them.
  struct Ref {
    double stamp;
    std::size_t agent, k;
  };
  std::vector<Ref> order;
  for (std::size_t i : due)
    for (std::size_t k = 0; k < agents_[i].held.size(); ++k)
      order.push_back({agents_[i].held[k].stamp, i, k});
  std::stable_sort(order.begin(), order.end(), [](const Ref& x, const Ref& y) {
    return x.stamp < y.stamp || (x.stamp == y.stamp && x.agent < y.agent);
  });
  for (const Ref& r : order) {
    const OfflineAgent::HeldSend& h = agents_[r.agent].held[r.k];
    transmit(r.agent, h.session, h.seq, h.frame);
  }
  for (std::size_t i : due) agents_[i].held.clear();
  for (std::size_t i : due)
    if (!status[i]) return status[i];
  return Status::Ok();
}

void OfflineRun::retryCarriedWindows(double t) {
  // After its last frame (or a landing) an agent makes no new windows; one it had to defer
  // (the link too slow or busy) is tried again every window period.
  for (OfflineAgent& a : agents_) {
    if ((a.next < a.frames && !a.landed) || !a.pipeline->hasCarriedWindow() || t + 1e-9 < a.next_retry) continue;
    a.pipeline->retryCarriedWindow(t);
    a.next_retry = t + params_.run.agent.tracker.window.period_s;
  }
}

void OfflineRun::onServerCreated(std::function<void(server::Server&)> setup) {
  server_setup_ = std::move(setup);
  if (server_ && server_setup_) server_setup_(*server_);
}

Status OfflineRun::restartServer(double t) {
  const std::vector<double>& at = params_.clock.server_restart_at;
  if (server_ && next_restart_ < at.size() && t + 1e-9 >= at[next_restart_]) {
    ++next_restart_;
    ServerRestart r;
    r.down_at_s = t;
    for (const OfflineAgent& a : agents_) r.resends_before += a.resent;
    restarts_.push_back(r);
    server_.reset();  // a crash: no clean checkpoint
    server_up_at_ = t + params_.clock.server_downtime_s;
  }
  if (server_ || t + 1e-9 < server_up_at_) return Status::Ok();
  const auto t0 = std::chrono::steady_clock::now();
  auto server = server::Server::create(params_.server, base_dir_);
  if (!server) return Error{"server restart at " + std::to_string(t) + " s: " + server.error()};
  server_ = std::move(*server);
  if (downlink_) downlink_->newEpoch(restarts_.size() + 1);
  ServerRestart& r = restarts_.back();
  r.up_at_s = t;
  r.resume_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  r.checkpoint = server_->resumeReport().checkpoint;
  r.problems = server_->resumeReport().problems;
  r.journal_replayed = server_->resumeReport().journal_replayed;
  if (server_setup_) server_setup_(*server_);
  // The robots see the server again (its acknowledgements resume) and resend
  // everything it has not acknowledged.
  for (OfflineAgent& a : agents_) a.pipeline->uplink()->onReconnect();
  if (network_) network_->onServerBack();
  next_server_ = t + params_.clock.server_period_s;
  return Status::Ok();
}

void OfflineRun::sampleHealth(double t) {
  HealthSample h;
  h.time_s = t;
  h.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start_).count();
  h.rss_bytes = residentBytes();
  for (const OfflineAgent& a : agents_) h.flying += !a.landed && a.next > 0 && a.next < a.frames;
  h.server_up = server_ != nullptr;
  if (server_) {
    h.state_bytes = server_->saveState().size();
    h.keyframes = server_->map().keyframeCount();
    h.landmarks = server_->map().landmarkCount();
    h.pending = server_->pending();
    h.merged = server_->counters().merged;
    h.agents_merged = server_->mapManager().agentsMerged();
    const TimingStats timings = server_->timings();
    const std::size_t n = timings.count("submap");
    if (n < health_submaps_) health_submaps_ = 0;  // a server resumed without its timings
    const auto it = timings.samples().find("submap");
    if (it != timings.samples().end()) {
      const std::vector<double>& v = it->second;
      const std::size_t fresh = std::min(n - health_submaps_, v.size());
      const std::vector<double> last(v.end() - static_cast<std::ptrdiff_t>(fresh), v.end());
      h.submaps = fresh;
      h.submap_ms_median = timing::percentile(last, 50);
      h.submap_ms_p95 = timing::percentile(last, 95);
    }
    health_submaps_ = n;
  }
  health_.push_back(h);
}

void OfflineRun::sample(double t) {
  const double period = params_.clock.sample_period_s;
  const LinkState st = link_->trace().at(next_sample_);
  std::optional<double> capacity;
  if (!link_->trace().unlimited()) capacity = st.rate_mbitps * 125.0;  // Mbit/s -> kB/s
  for (std::size_t i = 0; i < agents_.size(); ++i) {
    BandwidthSample b;
    b.time_s = next_sample_;
    b.agent = agents_[i].name;
    if (network_) {  // its own submaps on its first hop, partial messages counted as they go
      const double own = network_->ownBytes(i);
      b.kBps = (own - last_own_bytes_[i]) / period / 1000.0;
      b.link_capacity_kBps = network_->serverCapacityKBps(i, next_sample_);
      last_own_bytes_[i] = own;
    } else {
      const std::size_t tx = link_->transmittedBytes(static_cast<int>(i));
      b.kBps = double(tx - last_transmitted_[i]) / period / 1000.0;
      b.link_capacity_kBps = capacity;
      last_transmitted_[i] = tx;
    }
    bandwidth_.push_back(b);
    estimates_[agents_[i].name].emplace_back(
        t, agents_[i].pipeline->uplink()->monitor().estimate(t));
  }
  if (network_) network_->sample(next_sample_ + period, period);
}

Status OfflineRun::run(const std::function<void(const ProgressInfo&)>& progress) {
  const ClockParams& c = params_.clock;
  double end_frames = 0;
  std::size_t total = 0;
  for (const OfflineAgent& a : agents_) {
    end_frames = std::max(end_frames, a.dataset->frameTime(a.frames - 1) - a.clock_offset);
    total += a.frames;
  }
  const double end_all = end_frames + c.drain_s;
  next_sample_ = 0;
  next_server_ = c.server_period_s;
  double next_progress = 0;
  auto backlog = [&] {
    std::size_t b = 0;
    for (const OfflineAgent& a : agents_) b += a.pipeline->uplink()->buffer().pendingBytes();
    return b + acks_.size() + (network_ ? network_->pendingWork() : 0);
  };
  wall_start_ = std::chrono::steady_clock::now();
  next_health_ = 0;
  for (std::int64_t k = 0;; ++k) {
    const double t = double(k) * c.step_s;
    now_ = t;
    if (Status s = restartServer(t); !s) return s;
    if (Status s = resetAgents(t); !s) return s;
    deliver(t);
    acknowledge(t);
    if (downlink_) receiveDownlink(t);
    for (OfflineAgent& a : agents_) a.pipeline->pollUplink(t);
    if (network_) network_->poll(t, c.server_period_s);
    if (Status s = feedDueFrames(t); !s) return s;
    retryCarriedWindows(t);
    if (server_ && t + 1e-9 >= next_server_) {
      if (server_->process(t) > 0) sendGlobalPoses(t);
      if (downlink_) sendDownlink(t);
      next_server_ += c.server_period_s;
    }
    while (t + 1e-9 >= next_sample_ + c.sample_period_s) {
      sample(t);
      next_sample_ += c.sample_period_s;
    }
    if (c.health_period_s > 0 && t + 1e-9 >= next_health_) {
      sampleHealth(t);
      next_health_ += c.health_period_s;
    }
    if (stop_requested_.load() && !stopped_early_) {  // finish as at the end of the data
      stopped_early_ = true;
      for (OfflineAgent& a : agents_) {
        if (a.next >= a.frames) continue;
        a.frames = a.next;
        if (a.frames > 0 && !a.landed) a.pipeline->flushWindow();
      }
    }
    const bool frames_left = std::any_of(agents_.begin(), agents_.end(),
                                         [](const OfflineAgent& a) { return a.next < a.frames; });
    const bool carried = std::any_of(agents_.begin(), agents_.end(), [](const OfflineAgent& a) {
      return a.pipeline->hasCarriedWindow();
    });
    const bool done =
        stopped_early_ || (!frames_left && ((backlog() == 0 && !carried) || t >= end_all));
    if (progress && (t >= next_progress || done)) {
      ProgressInfo p;
      p.sim_time = t;
      p.sim_end = end_frames;
      for (const OfflineAgent& a : agents_) p.frames_done += a.next;
      p.frames_total = total;
      p.merged_submaps = server_ ? static_cast<int>(server_->counters().merged) : 0;
      p.agents_merged = server_ ? server_->mapManager().agentsMerged() : 0;
      p.draining = !frames_left;
      progress(p);
      next_progress = t + 1.0;
    }
    if (done) break;
  }
  // The last, partial sample period: the final window goes out after the last
  // frame, and its bytes belong in the bandwidth series and its mean / peak.
  if (now_ > next_sample_ + 1e-9) {
    sample(now_);
    next_sample_ += c.sample_period_s;
  }
  if (!server_) {  // the run ended while the server was down: bring it back to finish
    server_up_at_ = now_;
    if (Status s = restartServer(now_); !s) return s;
  }
  // Whatever arrived is merged, and the graph is optimised once more; the robots
  // hear where they ended up.
  server_->process(now_);
  // And the loop closures a budget deferred (server.map.closure_budget): the
  // server catches up before the final map is read.
  for (std::size_t n = server_->deferredClosures(); n > 0 && server_->deferredClosures() > 0; --n)
    server_->process(now_);  // each call verifies at least one
  if (Status s = server_->mapManager().optimize(/*full=*/true); !s) return s;
  sendGlobalPoses(now_);
  for (const PendingGlobal& g : globals_) agents_[g.agent].pipeline->onGlobalPose(g.update, g.time);
  globals_.clear();
  const Status saved = server_->checkpoint(now_);  // clean shutdown (no-op without a checkpoint directory)
  if (c.health_period_s > 0) sampleHealth(now_);    // the end state
  return saved;
}

}  // namespace hermes::system
