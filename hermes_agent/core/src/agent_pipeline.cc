#include "hermes/agent/agent_pipeline.h"

#include <chrono>
#include <cmath>

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
  // names etc.) even while the window hook is still a no-op.
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
      distiller_(std::move(distiller)) {}

Expected<TrackResult> AgentPipeline::feed(const CameraFrame& frame) {
  if (!std::isfinite(frame.stamp))
    return Error{"agent " + name_ + ": non-finite frame stamp"};
  if (frames_ > 0 && !(frame.stamp > last_stamp_))
    return Error{"agent " + name_ + ": frame stamp " + std::to_string(frame.stamp) +
                 " s is not after the previous one (" + std::to_string(last_stamp_) + " s)"};
  const auto t0 = std::chrono::steady_clock::now();
  auto result = tracker_.feed(frame);
  timings_.add("track", msSince(t0));
  if (!result.ok()) return Error{"agent " + name_ + ": " + result.error()};
  last_stamp_ = frame.stamp;
  ++frames_;
  if (result->status == TrackingStatus::kOk) {
    // Body pose in the odometry world: T_W_B = T_W_C * T_C_B.
    trajectory_.push_back(StampedPose{frame.stamp, result->T_W_C * T_C_B_});
  } else {
    ++lost_;
  }
  const auto t1 = std::chrono::steady_clock::now();
  windowStep(frame.stamp);
  timings_.add("window", msSince(t1));
  timings_.add("agent_total", msSince(t0));
  return result;
}

// HOOK: 5-s window -> distill -> encode -> uplink.
// TODO(mapping): needs Tracker::takeWindowIfDue(stamp) returning the finished
// 5-s window as a hermes::Submap (local mapping + window extraction, owned by
// the `mapping` engineer; not on main yet). When it exists this becomes:
//   if (auto window = tracker_.takeWindowIfDue(stamp)) {
//     distill::CoordinatorInput in{monitor.budgetRate(stamp), backlog, loops, probe};
//     auto r = distiller_->distill(*window, hint, in);            // timings "distill"
//     if (r.report.ok && !r.report.deferred) {
//       auto bytes = encodeSubmap(r.submap);                      // timings "encode"
//       uplink.submit(session, seq++, *bytes, stamp); ++submaps_sent_; bytes_sent_ += size;
//     }
//   }
// Until then no window is produced here (no fake windows): submaps/bytes stay 0.
void AgentPipeline::windowStep(double stamp) {
  (void)stamp;
  (void)distiller_;
}

AgentMetrics AgentPipeline::metrics() const {
  AgentMetrics m;
  m.agent = name_;
  m.lost_rate = lostRate();
  m.keyframes = static_cast<std::int64_t>(tracker_.keyframes().size());
  m.landmarks = static_cast<std::int64_t>(tracker_.landmarks().size());
  m.bytes = bytes_sent_;
  m.submaps_sent = submaps_sent_;
  return m;
}

}  // namespace hermes::agent
