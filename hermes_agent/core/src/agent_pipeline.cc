#include "hermes/agent/agent_pipeline.h"

#include <chrono>
#include <cmath>
#include <functional>

#include "hermes/core/stopwatch.h"
#include "hermes/core/wire_format.h"

namespace hermes::agent {

Expected<std::unique_ptr<AgentPipeline>> AgentPipeline::create(const AgentPipelineParams& params,
                                                               const std::string& name,
                                                               const AgentCamera& camera) {
  if (Status s = params.validate(); !s) return Error{s.error()};
  const PinholeIntrinsics& K = camera.K;
  if (!(K.fx > 0 && K.fy > 0 && std::isfinite(K.cx) && std::isfinite(K.cy) && K.width > 0 &&
        K.height > 0))
    return Error{"agent " + name + ": invalid camera intrinsics"};
  if (!(camera.baseline >= 0) || !std::isfinite(camera.baseline))
    return Error{"agent " + name + ": invalid stereo baseline"};
  if (!camera.T_B_C.translation().allFinite() || !camera.T_B_C.quat().coeffs().allFinite())
    return Error{"agent " + name + ": non-finite body<-camera extrinsic"};
  // The distiller is created now so that distill.* is validated (strategy
  // names etc.) even while the tracker hands out no windows.
  auto distiller = distill::Distiller::create(
      params.distill, [](const Submap& s) { return encodedSizeUncompressed(s); });
  if (!distiller.ok()) return Error{"agent " + name + ": " + distiller.error()};
  return std::unique_ptr<AgentPipeline>(
      new AgentPipeline(params, name, camera, std::move(*distiller)));
}

AgentPipeline::AgentPipeline(const AgentPipelineParams& params, const std::string& name,
                             const AgentCamera& camera,
                             std::unique_ptr<distill::Distiller> distiller)
    : params_(params),
      name_(name),
      camera_(camera),
      T_C_B_(camera.T_B_C.inverse()),
      tracker_(params.tracker, camera.K, camera.baseline),
      window_(tracker_, params.tracker.window),
      live_(tracker_, window_, T_C_B_),
      distiller_(std::move(distiller)),
      borrowed_([&] {
        BorrowedMapParams b = params.borrowed;
        b.octave_scale = params.tracker.orb.scale_factor;
        return b;
      }()),
      monitor_(params.uplink.monitor),
      timings_(static_cast<std::size_t>(params.threads.timing_window)),
      stage_timings_(static_cast<std::size_t>(params.threads.timing_window)) {
  // Agent identity in the window headers: a stable id from the agent's name.
  agent_id_ = agentUuid(name);
  window_.setAgent(agent_id_, session_);
  window_s_ = params.distill.window_s;
  startWorkers(params.threads.parallel);
}

AgentPipeline::~AgentPipeline() {
  // Queued windows are distilled and submitted (spooled), then the threads end;
  // the tracker joins its mapper thread itself.
  if (window_worker_) window_worker_->stop();
}

void AgentPipeline::startWorkers(bool parallel) {
  tracker_.setParallelMapping(parallel, mapper_hook_);
  if (!parallel) {
    window_worker_.reset();
    return;
  }
  window_worker_ = std::make_unique<StageWorker<WindowJob>>(
      true, static_cast<std::size_t>(params_.threads.window_queue),
      [this](WindowJob& job) { runWindowJob(job); },
      [](WindowJob& waiting, WindowJob&& incoming) {
        // Never dropped: the newer window joins the waiting one (one submap for
        // both periods); a retry folds into anything (the carry is merged anyway).
        if (incoming.window) {
          if (!waiting.window) {
            waiting.window = std::move(incoming.window);
          } else {
            auto merged = mergeWindows(std::move(*waiting.window), *incoming.window);
            // Same camera table within one agent: merging cannot fail; if it
            // did, the newer window is kept (the older one is counted failed).
            waiting.window = merged.ok() ? std::move(*merged) : std::move(*incoming.window);
            waiting.periods += incoming.periods;
          }
        }
        waiting.motion = incoming.motion;
        waiting.stamp = incoming.stamp;
        waiting.link_stamp = incoming.link_stamp;
      });
}

Status AgentPipeline::setParallel(bool parallel) {
  if (frames_ > 0) return Error{"agent " + name_ + ": choose the threading before the first frame"};
  if (parallel && (recording_ || replay_))
    return Error{"agent " + name_ + ": tracking record / replay needs synchronous mode (agent.parallel: false)"};
  params_.threads.parallel = parallel;
  startWorkers(parallel);
  return Status::Ok();
}

Status AgentPipeline::setMapperHook(std::function<void()> before_solve) {
  if (frames_ > 0) return Error{"agent " + name_ + ": set the mapper hook before the first frame"};
  mapper_hook_ = std::move(before_solve);
  tracker_.setParallelMapping(params_.threads.parallel, mapper_hook_);
  return Status::Ok();
}

Status AgentPipeline::attachUplink(UplinkSender::Transport transport, double clock_offset_s) {
  if (uplink_) return Error{"agent " + name_ + ": uplink already attached"};
  if (frames_ > 0) return Error{"agent " + name_ + ": attach the uplink before the first frame"};
  if (!std::isfinite(clock_offset_s)) return Error{"agent " + name_ + ": non-finite clock offset"};
  auto sender = UplinkSender::create(params_.uplink, std::move(transport), name_);
  if (!sender.ok()) return Error{"agent " + name_ + ": uplink: " + sender.error()};
  auto session = sender->buffer().newSession();
  if (!session.ok()) return Error{"agent " + name_ + ": uplink: " + session.error()};
  {
    std::lock_guard<std::mutex> lock(uplink_mu_);
    uplink_ = std::make_unique<UplinkSender>(std::move(*sender));
  }
  session_ = *session;
  clock_offset_ = clock_offset_s;
  window_.setAgent(agent_id_, session_);
  return Status::Ok();
}

bool AgentPipeline::onGlobalPose(const GlobalPoseUpdate& update, double now) {
  std::lock_guard<std::mutex> lock(global_mu_);
  if (!global_pose_.update(update, session_, now)) return false;
  if (!placements_.empty() && placements_.back().session == update.session &&
      placements_.back().placed < 0)
    placements_.back().placed = now;
  return true;
}

double AgentPipeline::uplinkTime(double stamp) const {
  std::lock_guard<std::mutex> lock(uplink_mu_);
  return uplink_clock_ ? uplink_clock_() : stamp - clock_offset_;
}

Expected<MapDownAck> AgentPipeline::onMapDown(const std::uint8_t* data, std::size_t size, double now) {
  (void)now;
  auto packet = decodeMapDown(data, size, "agent " + name_ + " map_down");
  if (!packet) return Error{packet.error()};
  std::string why;
  IngestResult r;
  {
    std::lock_guard<std::mutex> lock(borrowed_mu_);
    r = borrowed_.ingest(*packet, agent_id_, &why);
  }
  if (r == IngestResult::kRefused) return Error{"agent " + name_ + " map_down: " + why};
  return MapDownAck{agent_id_, packet->epoch, packet->seq};
}

AgentPipeline::BorrowedStats AgentPipeline::borrowedStats() const {
  std::lock_guard<std::mutex> lock(borrowed_mu_);
  BorrowedStats s;
  s.packets = borrowed_.packetsTaken();
  s.duplicates = borrowed_.duplicates();
  s.refused = borrowed_.refused();
  s.keyframes = borrowed_.keyframes();
  s.landmarks = borrowed_.landmarks();
  s.memory_bytes = borrowed_.memoryBytes();
  s.attempts = borrowed_attempts_;
  s.relocalisations = borrowed_relocalisations_;
  return s;
}

void AgentPipeline::placeByBorrowedMap(double stamp) {
  const std::vector<Keyframe>& kfs = tracker_.keyframes();
  if (kfs.empty()) return;
  const Keyframe& kf = kfs.back();
  std::optional<SE3> T_W_C;
  {
    std::lock_guard<std::mutex> lock(global_mu_);
    const auto& held = global_pose_.latest();
    if (held && held->session == session_) T_W_C = global_pose_.inWorld(kf.T_A_C);
  }
  std::lock_guard<std::mutex> lock(borrowed_mu_);
  if (T_W_C) {  // placed: the borrowed map keeps what lies around the robot
    borrowed_.setRobotPosition(T_W_C->translation());
    return;
  }
  if (borrowed_.landmarks() == 0) return;
  const auto t0 = std::chrono::steady_clock::now();
  ++borrowed_attempts_;
  auto r = borrowed_.relocalise(kf.keypoints, kf.descriptors, camera_.K, camera_.baseline,
                                params_.tracker.pose);
  timings_.add("borrowed_relocalise", msSince(t0));
  if (!r) return;
  GlobalPoseUpdate u;
  u.session = session_;
  u.keyframe_stamp = kf.stamp;
  u.T_W_O = r->T_W_C * kf.T_A_C.inverse();
  const double now = uplinkTime(stamp);
  std::lock_guard<std::mutex> glock(global_mu_);
  if (!global_pose_.update(u, session_, now)) return;
  ++borrowed_relocalisations_;
  if (!placements_.empty() && placements_.back().session == session_ && placements_.back().placed < 0) {
    placements_.back().placed = now;
    placements_.back().by_borrowed = true;
  }
}

Status AgentPipeline::onAck(std::uint32_t session, std::uint64_t seq, double now) {
  std::lock_guard<std::mutex> lock(uplink_mu_);
  if (!uplink_) return Error{"agent " + name_ + ": acknowledgement without an uplink"};
  if (last_window_ && *last_window_ == std::make_pair(session, seq)) last_window_acked_ = true;
  return uplink_->onAck(session, seq, now);
}

Status AgentPipeline::onHandedOver(std::uint32_t session, std::uint64_t seq, double now) {
  std::lock_guard<std::mutex> lock(uplink_mu_);
  if (!uplink_) return Error{"agent " + name_ + ": hop acknowledgement without an uplink"};
  if (last_window_ && *last_window_ == std::make_pair(session, seq)) last_window_acked_ = true;
  uplink_->onHandedOver(session, seq, now);
  return Status::Ok();
}

void AgentPipeline::onUplinkReconnect() {
  std::lock_guard<std::mutex> lock(uplink_mu_);
  if (uplink_) uplink_->onReconnect();
}

void AgentPipeline::pollUplink(double now) {
  std::lock_guard<std::mutex> lock(uplink_mu_);
  if (uplink_) uplink_->poll(now);
}

Status AgentPipeline::checkStamp(double stamp) const {
  if (!std::isfinite(stamp)) return Error{"agent " + name_ + ": non-finite frame stamp"};
  if (frames_ > 0 && !(stamp > last_stamp_))
    return Error{"agent " + name_ + ": frame stamp " + std::to_string(stamp) +
                 " s is not after the previous one (" + std::to_string(last_stamp_) + " s)"};
  return Status::Ok();
}

Expected<TrackResult> AgentPipeline::feed(const CameraFrame& frame) {
  if (!front_->needsImages())
    return Error{"agent " + name_ + ": replaying a tracking recording: no frames to feed"};
  auto step = trackStep(&frame, frame.stamp);
  if (!step.ok()) return Error{step.error()};
  return std::move(step->result);
}

Expected<TrackingStatus> AgentPipeline::replayFrame(double stamp) {
  if (!replay_) return Error{"agent " + name_ + ": not replaying a tracking recording"};
  auto step = trackStep(nullptr, stamp);
  if (!step.ok()) return Error{step.error()};
  return step->result.status;
}

Expected<FrontStep> AgentPipeline::trackStep(const CameraFrame* frame, double stamp) {
  if (Status s = checkStamp(stamp); !s) return Error{s.error()};
  const auto t0 = std::chrono::steady_clock::now();
  auto step = front_->track(frame, stamp);
  if (frame) timings_.add("track", msSince(t0));

  if (!step.ok()) return Error{"agent " + name_ + ": " + step.error()};
  last_stamp_ = stamp;
  ++frames_;
  if (step->result.status == TrackingStatus::kOk) {
    lost_since_ = -1;
  } else if (step->result.status == TrackingStatus::kLost) {
    if (lost_since_ < 0) lost_since_ = stamp;
    const double after = params_.tracker.reinit_after_s;
    if (after > 0 && stamp - lost_since_ >= after && front_->startsNewMaps()) {
      startNewMap();
      step = front_->track(frame, stamp);  // the new map starts from this frame if it can
      if (!step.ok()) return Error{"agent " + name_ + ": " + step.error()};
    }
  }
  bool new_session;
  {
    std::lock_guard<std::mutex> lock(global_mu_);
    new_session = placements_.empty() || placements_.back().session != session_;
  }
  if (new_session) {  // (the uplink clock only then: its lock may wait on a send)
    const double now = uplinkTime(stamp);
    std::lock_guard<std::mutex> lock(global_mu_);
    placements_.push_back({session_, now});
  }
  if (step->result.status == TrackingStatus::kOk) {
    trajectory_.push_back(StampedPose{stamp, step->T_W_B});
    if (step->result.new_keyframe && frame) placeByBorrowedMap(stamp);
  } else {
    ++lost_;
  }
  const auto t1 = std::chrono::steady_clock::now();
  if (window_worker_)
    queueWindowStep(stamp, stamp);
  else
    windowStep(stamp);
  timings_.add("window", msSince(t1));
  timings_.add("agent_total", msSince(t0));
  if (Status s = front_->endStep(&*step, stamp); !s) return Error{"agent " + name_ + ": " + s.error()};
  return step;
}

void AgentPipeline::stackFronts() {
  if (replay_) {
    front_ = replay_.get();
    return;
  }
  TrackingFront* front = &live_;
  if (corrupted_) {
    corrupted_->wrap(front);
    front = corrupted_.get();
  }
  if (recording_) {
    recording_->wrap(front);
    front = recording_.get();
  }
  front_ = front;
}

Status AgentPipeline::recordTracking(std::unique_ptr<TrackingLogWriter> writer) {
  if (frames_ > 0 || replay_ || recording_)
    return Error{"agent " + name_ + ": start recording before the first frame, once, not while replaying"};
  if (window_worker_)
    return Error{"agent " + name_ + ": tracking record needs synchronous mode (agent.parallel: false)"};
  recording_ = std::make_unique<RecordingFront>(std::move(writer));
  stackFronts();
  return Status::Ok();
}

Status AgentPipeline::finishTracking() {
  if (Status s = front_->finish(frames_, lost_); !s) return Error{"agent " + name_ + ": " + s.error()};
  return Status::Ok();
}

Status AgentPipeline::replayTracking(TrackingLog log) {
  if (frames_ > 0 || replay_ || recording_)
    return Error{"agent " + name_ + ": start replaying before the first frame, once, not while recording"};
  if (window_worker_)
    return Error{"agent " + name_ + ": tracking replay needs synchronous mode (agent.parallel: false)"};
  replay_ = std::make_unique<ReplayFront>(std::move(log));
  replay_->setAgent(agent_id_, session_);
  stackFronts();
  return Status::Ok();
}

Status AgentPipeline::submitWindow(const Submap& submap, std::vector<std::uint8_t>&& bytes, double now) {
  // Whether the previous window arrived before this one was planned decides
  // the monitor's probing (DESIGN §3).
  if (last_window_) uplink_->monitor().onWindowDelivered(last_window_acked_);
  const auto key = std::make_pair(submap.header.session, submap.header.seq);
  Status s = uplink_->submit(key.first, key.second, std::move(bytes), now);
  if (s) {
    last_window_ = key;
    last_window_acked_ = false;
    submitted_.push_back(key);
  }
  return s;
}

WindowSink AgentPipeline::makeSink(double now, double backlog_bytes, std::mutex* lock) {
  WindowSink sink;
  sink.link_now = now;
  sink.backlog_bytes = backlog_bytes;
  sink.loop_closures = loop_closures_.load();
  sink.placed = globalPose().latest().has_value();
  sink.submit = [this, now, lock](const Submap& submap, std::vector<std::uint8_t>&& bytes) -> Status {
    if (!lock) return submitWindow(submap, std::move(bytes), now);
    std::lock_guard<std::mutex> guard(*lock);
    return submitWindow(submap, std::move(bytes), now);
  };
  return sink;
}

void AgentPipeline::windowStep(double stamp, bool retry_carry) {
  TrackingFront& source = *front_;
  if (!uplink_) {
    if (retry_carry)
      agent::retryCarriedWindow(source, *distiller_, monitor_, stamp, &windows_, &timings_);
    else
      runWindowStep(source, *distiller_, monitor_, stamp, &windows_, &timings_);
    return;
  }
  const double now = uplink_clock_ ? uplink_clock_()
                                   : (retry_carry ? stamp : last_stamp_) - clock_offset_;
  const WindowSink sink = makeSink(now, static_cast<double>(uplink_->backlogBytes()), nullptr);
  if (retry_carry)
    agent::retryCarriedWindow(source, *distiller_, uplink_->monitor(), stamp, &windows_, &timings_, &sink);
  else
    runWindowStep(source, *distiller_, uplink_->monitor(), stamp, &windows_, &timings_, &sink);
  uplink_->poll(now);
}

void AgentPipeline::setOdometryCorruption(const OdometryCorruptionParams& params) {
  corrupted_ = std::make_unique<CorruptedFront>(params, tracker_);
  stackFronts();
}

void AgentPipeline::retryCarriedWindow(double now) {
  if (window_worker_) {
    if (!hasCarriedWindow()) return;
    WindowJob job;
    job.stamp = job.link_stamp = now + clock_offset_;
    ++window_retries_;
    window_worker_->push(std::move(job));
    return;
  }
  if (!windows_.carry) return;
  // The uplink clock is the stamp clock shifted by the offset (or its own clock).
  windowStep(now + clock_offset_, /*retry_carry=*/true);
}

void AgentPipeline::startNewMap() {
  flushWindow();  // the old map's open window goes out under the old session
  // A carried or held-back window of the old session cannot join a window of the
  // new one (its keyframe ids start again): try it once more, else drop it (counted).
  if (window_worker_) {
    if (hasCarriedWindow()) {
      retryCarriedWindow(last_stamp_ - clock_offset_);
      window_worker_->waitIdle();
    }
    WindowJob drop;
    drop.drop_carry = true;
    drop.stamp = drop.link_stamp = last_stamp_;
    window_worker_->push(std::move(drop));
    window_worker_->waitIdle();
  } else {
    if (windows_.carry) windowStep(last_stamp_, /*retry_carry=*/true);
    if (windows_.carry) {
      windows_.carry_dropped_keyframes += static_cast<std::int64_t>(windows_.carry->keyframes.size());
      ++windows_.failed;
      windows_.carry.reset();
    }
    windows_.held.reset();
  }
  // The new map continues the odometry frame from the last body pose.
  const SE3 T_W_B = trajectory_.empty() ? SE3() : trajectory_.back().T_W_B;
  tracker_.startNewMap(T_W_B * T_C_B_.inverse());
  window_.restart();
  if (uplink_) {
    std::lock_guard<std::mutex> lock(uplink_mu_);
    auto session = uplink_->buffer().newSession();
    session_ = session.ok() ? *session : session_ + 1;
  } else {
    ++session_;
  }
  window_.setAgent(agent_id_, session_);
  ++new_maps_;
  lost_since_ = -1;
}

void AgentPipeline::flushWindow() {
  if (frames_ == 0) return;
  if (window_worker_) {
    tracker_.finishMapping();  // every keyframe adjusted: the whole map can go
    window_worker_->waitIdle();
    queueWindowStep(last_stamp_ + params_.tracker.window.period_s + 1e-6, last_stamp_);
    window_worker_->waitIdle();
    return;
  }
  // A stamp one window period after the last frame makes the open window due.
  const double stamp = last_stamp_ + params_.tracker.window.period_s + 1e-6;
  if (!front_->beginFlush(stamp)) return;  // a replay out of step: finishTracking() reports it
  windowStep(stamp);
  (void)front_->endStep(nullptr, stamp);  // a recording's error: finishTracking() reports it
}

AgentMetrics AgentPipeline::metrics() const {
  AgentMetrics m;
  m.agent = name_;
  m.lost_rate = lostRate();
  const TrackingSummary tracked = front_->summary();
  m.keyframes = tracked.keyframes;
  m.landmarks = tracked.landmarks;
  const WindowCounters w = windows();
  m.bytes = w.bytes;
  m.submaps_sent = w.sent;
  m.submaps_deferred = w.deferred + w.refused;
  m.weak_frames = tracked.total_health.weak;
  m.trouble_windows = w.trouble;
  m.new_maps = new_maps_;
  const BorrowedStats b = borrowedStats();
  m.borrowed_relocalisations = b.relocalisations;
  m.borrowed_landmarks = static_cast<std::int64_t>(b.landmarks);
  m.borrowed_memory_bytes = static_cast<std::int64_t>(b.memory_bytes);
  return m;
}

WindowCounters AgentPipeline::windows() const {
  if (!window_worker_) return windows_;
  std::lock_guard<std::mutex> lock(stats_mu_);
  return windows_;
}

bool AgentPipeline::hasCarriedWindow() const {
  if (!window_worker_) return windows_.carry.has_value();
  std::lock_guard<std::mutex> lock(stats_mu_);
  return carry_pending_;
}

TimingStats AgentPipeline::timings() const {
  TimingStats t = timings_;
  if (window_worker_) {
    std::lock_guard<std::mutex> lock(stats_mu_);
    t.merge(stage_timings_);
  }
  return t;
}

AgentThreadStats AgentPipeline::threadStats() const {
  AgentThreadStats s;
  s.parallel = window_worker_ != nullptr;
  s.frames_fed = frames_;
  s.frames_tracked = frames_ - lost_;
  s.mapping = tracker_.mappingStats();
  if (window_worker_) s.windows = window_worker_->stats();
  s.window_retries = window_retries_;
  return s;
}

void AgentPipeline::queueWindowStep(double stamp, double link_stamp) {
  std::optional<Submap> window = front_->takeWindowIfDue(stamp);
  WindowJob job;
  job.stamp = stamp;
  job.link_stamp = link_stamp;
  if (window) {
    job.window = std::move(window);
    job.motion = front_->motionHint();
  } else {
    // No new window (the robot stands still): a carried one is retried once a
    // period, as runWindowStep does (the published state may be a job old).
    std::lock_guard<std::mutex> lock(stats_mu_);
    if (!carry_pending_ || stamp - carry_stamp_ < window_s_) return;
    carry_stamp_ = stamp;  // one retry per period, even before the job ran
    ++window_retries_;
  }
  window_worker_->push(std::move(job));
}

void AgentPipeline::runWindowJob(WindowJob& job) {
  // Plan with a copy of the monitor and the backlog taken now: the uplink lock
  // is held only to read them and to submit, never while distilling.
  BandwidthMonitor monitor = monitor_;
  double now = 0, backlog = 0;
  bool have_uplink = false;
  {
    std::lock_guard<std::mutex> lock(uplink_mu_);
    now = uplink_clock_ ? uplink_clock_() : job.link_stamp - clock_offset_;
    if (uplink_) {
      have_uplink = true;
      monitor = uplink_->monitor();
      backlog = static_cast<double>(uplink_->backlogBytes());
    }
  }
  const WindowSink sink = makeSink(now, backlog, &uplink_mu_);
  const WindowSink* out = have_uplink ? &sink : nullptr;
  WindowCounters& c = stage_windows_;
  TimingStats t;
  if (job.drop_carry) {
    if (c.carry) {
      c.carry_dropped_keyframes += static_cast<std::int64_t>(c.carry->keyframes.size());
      ++c.failed;
      c.carry.reset();
    }
    c.held.reset();
  } else if (!job.window) {
    if (c.carry) {
      Submap carried = std::move(*c.carry);
      c.carry.reset();
      distilAndSubmit(std::move(carried), c.carry_periods + 1, job.motion, *distiller_, monitor,
                      job.stamp, &c, &t, out);
    }
  } else {  // as runWindowStep: the carried window joins the new one
    c.windows += job.periods;
    c.window_bytes += static_cast<std::int64_t>(encodedSizeUncompressed(*job.window));
    int periods = job.periods;
    Submap window = std::move(*job.window);
    if (c.carry) {
      auto merged = mergeWindows(std::move(*c.carry), window);
      c.carry.reset();
      if (merged.ok()) {
        window = std::move(*merged);
        ++c.carried;
        periods += c.carry_periods;
      } else {
        ++c.failed;
      }
      c.carry_dropped_keyframes +=
          static_cast<std::int64_t>(keepNewestKeyframes(&window, kMaxCarryKeyframes));
    }
    distilAndSubmit(std::move(window), periods, job.motion, *distiller_, monitor, job.stamp, &c,
                    &t, out);
  }
  {
    std::lock_guard<std::mutex> lock(uplink_mu_);
    if (uplink_) uplink_->poll(now);
  }
  publishWindowCounters(t);
}

void AgentPipeline::publishWindowCounters(const TimingStats& job_timings) {
  // Counters without the carried / held maps (they stay with the uplink thread).
  std::optional<Submap> carry, held;
  carry.swap(stage_windows_.carry);
  held.swap(stage_windows_.held);
  WindowCounters copy = stage_windows_;
  carry.swap(stage_windows_.carry);
  held.swap(stage_windows_.held);
  std::lock_guard<std::mutex> lock(stats_mu_);
  windows_ = std::move(copy);
  stage_timings_.merge(job_timings);
  carry_pending_ = stage_windows_.carry.has_value();
  if (carry_pending_) carry_stamp_ = stage_windows_.carry_stamp;
}

}  // namespace hermes::agent
