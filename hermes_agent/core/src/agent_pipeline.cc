#include "hermes/agent/agent_pipeline.h"

#include <chrono>
#include <cmath>
#include <functional>

#include "hermes/core/wire_format.h"

namespace hermes::agent {
namespace {

double msSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0)
      .count();
}

}  // namespace

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
      distiller_(std::move(distiller)),
      monitor_(params.uplink.monitor) {
  // Agent identity in the window headers: a stable id from the agent's name.
  agent_id_ = uuidFromSeed(std::hash<std::string>{}(name));
  setWindowIdentity(tracker_, agent_id_, session_);
}

Status AgentPipeline::attachUplink(UplinkSender::Transport transport, double clock_offset_s) {
  if (uplink_) return Error{"agent " + name_ + ": uplink already attached"};
  if (frames_ > 0) return Error{"agent " + name_ + ": attach the uplink before the first frame"};
  if (!std::isfinite(clock_offset_s)) return Error{"agent " + name_ + ": non-finite clock offset"};
  auto sender = UplinkSender::create(params_.uplink, std::move(transport));
  if (!sender.ok()) return Error{"agent " + name_ + ": uplink: " + sender.error()};
  auto session = sender->buffer().newSession();
  if (!session.ok()) return Error{"agent " + name_ + ": uplink: " + session.error()};
  uplink_ = std::make_unique<UplinkSender>(std::move(*sender));
  session_ = *session;
  clock_offset_ = clock_offset_s;
  setWindowIdentity(tracker_, agent_id_, session_);
  return Status::Ok();
}

Status AgentPipeline::onAck(std::uint32_t session, std::uint64_t seq, double now) {
  if (!uplink_) return Error{"agent " + name_ + ": acknowledgement without an uplink"};
  if (last_window_ && *last_window_ == std::make_pair(session, seq)) last_window_acked_ = true;
  return uplink_->onAck(session, seq, now);
}

void AgentPipeline::pollUplink(double now) {
  if (uplink_) uplink_->poll(now);
}

Expected<TrackResult> AgentPipeline::feed(const CameraFrame& frame) {
  if (!std::isfinite(frame.stamp))
    return Error{"agent " + name_ + ": non-finite frame stamp"};
  if (frames_ > 0 && !(frame.stamp > last_stamp_))
    return Error{"agent " + name_ + ": frame stamp " + std::to_string(frame.stamp) +
                 " s is not after the previous one (" + std::to_string(last_stamp_) + " s)"};
  const auto t0 = std::chrono::steady_clock::now();
  if (corruptor_ && corruptor_->noticedJumpAt(frame.stamp)) tracker_.markLost();
  auto result = tracker_.feed(frame);
  timings_.add("track", msSince(t0));
  if (!result.ok()) return Error{"agent " + name_ + ": " + result.error()};
  last_stamp_ = frame.stamp;
  ++frames_;
  if (result->status == TrackingStatus::kOk) {
    // Body pose in the odometry world: T_W_B = T_W_C * T_C_B.
    SE3 T_W_B = result->T_W_C * T_C_B_;
    if (corruptor_) T_W_B = corruptor_->onFrame(frame.stamp, T_W_B) * T_W_B;
    trajectory_.push_back(StampedPose{frame.stamp, T_W_B});
  } else {
    ++lost_;
  }
  const auto t1 = std::chrono::steady_clock::now();
  windowStep(frame.stamp);
  timings_.add("window", msSince(t1));
  timings_.add("agent_total", msSince(t0));
  return result;
}

void AgentPipeline::windowStep(double stamp, bool retry_carry) {
  if (!uplink_) {
    if (retry_carry)
      agent::retryCarriedWindow(tracker_, *distiller_, monitor_, stamp, &windows_, &timings_);
    else
      runWindowStep(tracker_, *distiller_, monitor_, stamp, &windows_, &timings_);
    return;
  }
  const double now = uplink_clock_ ? uplink_clock_()
                                   : (retry_carry ? stamp : last_stamp_) - clock_offset_;
  WindowSink sink;
  sink.link_now = now;
  sink.backlog_bytes = static_cast<double>(uplink_->backlogBytes());
  sink.loop_closures = loop_closures_;
  sink.submit = [&](const Submap& submap, std::vector<std::uint8_t>&& bytes) -> Status {
    // Whether the previous window arrived before this one was planned decides
    // the monitor's probing (DESIGN §3).
    if (last_window_) uplink_->monitor().onWindowDelivered(last_window_acked_);
    const auto key = std::make_pair(submap.header.session, submap.header.seq);
    Status s = uplink_->submit(key.first, key.second, std::move(bytes), now);
    if (s) {
      last_window_ = key;
      last_window_acked_ = false;
    }
    return s;
  };
  if (retry_carry)
    agent::retryCarriedWindow(tracker_, *distiller_, uplink_->monitor(), stamp, &windows_, &timings_, &sink);
  else
    runWindowStep(tracker_, *distiller_, uplink_->monitor(), stamp, &windows_, &timings_, &sink);
  uplink_->poll(now);
}

void AgentPipeline::setOdometryCorruption(const OdometryCorruptionParams& params) {
  corruptor_ = std::make_unique<OdometryCorruptor>(params);
  tracker_.setWindowHook([c = corruptor_.get()](Submap* w) { c->apply(w); });
}

void AgentPipeline::retryCarriedWindow(double now) {
  if (!windows_.carry) return;
  // The uplink clock is the stamp clock shifted by the offset (or its own clock).
  windowStep(now + clock_offset_, /*retry_carry=*/true);
}

void AgentPipeline::flushWindow() {
  if (frames_ == 0) return;
  // A stamp one window period after the last frame makes the open window due.
  windowStep(last_stamp_ + params_.tracker.window.period_s + 1e-6);
}

AgentMetrics AgentPipeline::metrics() const {
  AgentMetrics m;
  m.agent = name_;
  m.lost_rate = lostRate();
  m.keyframes = static_cast<std::int64_t>(tracker_.keyframes().size());
  m.landmarks = static_cast<std::int64_t>(tracker_.landmarks().size());
  m.bytes = windows_.bytes;
  m.submaps_sent = windows_.sent;
  m.submaps_deferred = windows_.deferred + windows_.refused;
  return m;
}

}  // namespace hermes::agent
