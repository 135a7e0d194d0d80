// The agent's window step: every window period the window source hands over the
// map since the previous window as a Submap, which is distilled under the uplink
// budget and encoded. A window source has takeWindowIfDue(stamp) and
// motionHint(): the pipeline's tracking front (tracking_front.h: the live window
// cut, or a wrapper that corrupts, records or replays it).
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <optional>
#include <utility>
#include <vector>

#include "hermes/agent/bandwidth_monitor.h"
#include "hermes/agent/submap_window.h"
#include "hermes/core/metrics.h"
#include "hermes/core/wire_format.h"
#include "hermes/distill/distiller.h"

namespace hermes::agent {

/// A window that could not be sent is not lost: it is carried and merged into
/// the next window (mergeWindows), whose distillation then decides what of both
/// fits the budget. Over a long outage the carried map is bounded to its newest
/// kMaxCarryKeyframes keyframes (the oldest are dropped and counted).
constexpr std::size_t kMaxCarryKeyframes = 400;

/// Counters of the window step, and the carried window.
struct WindowCounters {
  std::int64_t windows = 0, sent = 0, deferred = 0, failed = 0;
  std::int64_t refused = 0;  ///< encoded but refused by the uplink's buffer (full)
  std::int64_t bytes = 0;  ///< encoded bytes of the sent submaps
  /// Encoded size of every window as cut, before distillation: what raw streaming
  /// (distill.strategy none) of the same windows would send on a link that keeps up.
  std::int64_t window_bytes = 0;
  std::int64_t trouble = 0;  ///< windows sent as in trouble (DistillReport::trouble)
  std::int64_t carried = 0;  ///< windows merged into a later one after deferral / refusal
  std::int64_t carry_dropped_keyframes = 0;  ///< dropped by the kMaxCarryKeyframes bound
  std::optional<Submap> carry;  ///< deferred / refused window waiting for the next
  int carry_periods = 0;        ///< window periods the carried window stands for
  double carry_stamp = 0;       ///< [s] when it was last deferred / refused
  /// Keypoints a window planned before the link was measured held back
  /// (DistillResult::held_back): the next window on a link that keeps up sends
  /// them as keyframe extensions; once the link is measured otherwise they go.
  std::optional<Submap> held;
  std::int64_t extended_keyframes = 0;  ///< keyframe extensions sent
};

/// Where a window step's encoded submap goes. Without a sink (no uplink) the
/// submap is only counted, the link is unknown: the budget comes from the
/// monitor's planning rate (its initial guess) and the backlog is zero.
struct WindowSink {
  double link_now = 0;        ///< [s] uplink clock for the monitor
  double backlog_bytes = 0;   ///< unacknowledged bytes in the uplink
  int loop_closures = 0;      ///< loops the server reported (alpha rule)
  bool placed = true;         ///< the server placed the robot in the global map (CoordinatorInput::placed)
  /// Takes the encoded frame; an error counts the window as refused.
  std::function<Status(const Submap& submap, std::vector<std::uint8_t>&& frame)> submit;
};

/// Distils `window` (standing for `periods` window periods) under the budget,
/// encodes it and hands it to the sink; a deferred or refused window becomes the
/// carry. Timings: "distill", "encode".
inline void distilAndSubmit(Submap window, int periods, const distill::MotionHint& motion,
                            distill::Distiller& distiller, const BandwidthMonitor& monitor,
                            double stamp, WindowCounters* counters, TimingStats* timings,
                            const WindowSink* sink) {
  distill::CoordinatorInput in;
  in.bandwidth_Bps = monitor.planningRate(sink ? sink->link_now : stamp);
  in.backlog_bytes = sink ? sink->backlog_bytes : 0;
  in.loop_closures = sink ? sink->loop_closures : 0;
  in.placed = sink ? sink->placed : true;
  in.link_keeps_up = sink && monitor.samples() > 0 && sink->backlog_bytes <= 0 && periods == 1;
  in.link_unmeasured = sink && monitor.samples() == 0;
  in.period_s = periods * distiller.params().window_s;
  const auto t0 = std::chrono::steady_clock::now();
  distill::DistillResult r = distiller.distill(window, motion, in);
  const auto t1 = std::chrono::steady_clock::now();
  timings->add("distill", std::chrono::duration<double, std::milli>(t1 - t0).count());
  if (!r.report.ok) {
    ++counters->failed;
    return;
  }
  if (r.held_back) {
    counters->held = std::move(r.held_back);
  } else if (counters->held && in.link_keeps_up && !r.report.deferred) {
    distiller.extendWithHeldBack(*counters->held, &r);
    counters->extended_keyframes += r.report.extension_keyframes;
    counters->held.reset();
  } else if (counters->held && monitor.samples() > 0) {
    counters->held.reset();  // the link is measured and has no room for them
  }
  auto keep = [&] {
    counters->carry = std::move(window);
    counters->carry_periods = periods;
    counters->carry_stamp = stamp;
  };
  if (r.report.deferred) {
    ++counters->deferred;
    keep();
    return;
  }
  auto bytes = encodeSubmap(r.submap);
  timings->add("encode",
               std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t1).count());
  if (!bytes.ok()) {
    ++counters->failed;
    return;
  }
  const auto size = static_cast<std::int64_t>(bytes->size());
  if (sink && sink->submit) {
    if (Status s = sink->submit(r.submap, std::move(*bytes)); !s) {
      ++counters->refused;
      keep();
      return;
    }
  }
  ++counters->sent;
  if (r.report.trouble) ++counters->trouble;
  counters->bytes += size;
}

template <typename Source>
void retryCarriedWindow(Source& source, distill::Distiller& distiller,
                        const BandwidthMonitor& monitor, double stamp, WindowCounters* counters,
                        TimingStats* timings, const WindowSink* sink = nullptr);

/// One window step at time `stamp` [s]: the source's due window, merged with
/// the carried one, distilled and submitted. Without a new window (no new
/// keyframes: the robot stands still) a carried one is retried once a period.
template <typename Source>
void runWindowStep(Source& source, distill::Distiller& distiller,
                   const BandwidthMonitor& monitor, double stamp, WindowCounters* counters,
                   TimingStats* timings, const WindowSink* sink = nullptr) {
  std::optional<Submap> window = source.takeWindowIfDue(stamp);
  if (!window) {
    if (counters->carry && stamp - counters->carry_stamp >= distiller.params().window_s)
      retryCarriedWindow(source, distiller, monitor, stamp, counters, timings, sink);
    return;
  }
  ++counters->windows;
  counters->window_bytes += static_cast<std::int64_t>(encodedSizeUncompressed(*window));
  int periods = 1;
  if (counters->carry) {
    auto merged = mergeWindows(std::move(*counters->carry), *window);
    counters->carry.reset();
    if (merged.ok()) {
      *window = std::move(*merged);
      ++counters->carried;
      periods += counters->carry_periods;
    } else {
      ++counters->failed;  // camera changed: the carried window cannot join this one
    }
    counters->carry_dropped_keyframes +=
        static_cast<std::int64_t>(keepNewestKeyframes(&*window, kMaxCarryKeyframes));
  }
  distilAndSubmit(std::move(*window), periods, source.motionHint(), distiller, monitor, stamp,
                  counters, timings, sink);
}

/// When no new window comes (the sequence ended, the robot stands still), the
/// carried window is tried again: it now stands for one more period of the link.
template <typename Source>
void retryCarriedWindow(Source& source, distill::Distiller& distiller,
                        const BandwidthMonitor& monitor, double stamp, WindowCounters* counters,
                        TimingStats* timings, const WindowSink* sink) {
  if (!counters->carry) return;
  Submap window = std::move(*counters->carry);
  counters->carry.reset();
  distilAndSubmit(std::move(window), counters->carry_periods + 1, source.motionHint(),
                  distiller, monitor, stamp, counters, timings, sink);
}

}  // namespace hermes::agent
