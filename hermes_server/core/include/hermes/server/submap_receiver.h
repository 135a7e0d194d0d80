// Server side of exactly-once delivery: checks and decodes an incoming frame,
// asks the bookkeeper whether it is new, hands each accepted submap exactly once
// to the sink (the credibility queue / map manager) and says how to acknowledge.
// Malformed, oversized, wrong-version or unknown-agent frames are rejected with
// a reason and never disturb other agents. Transport-agnostic: the ROS node and
// the offline runner both call receive().
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "hermes/core/wire_format.h"
#include "hermes/server/bookkeeper.h"

namespace hermes {

struct ReceivedSubmap {
  RobotId robot = 0;
  Submap submap;
  std::size_t bytes = 0;  ///< frame size as received
  double arrival_time = 0;
};

struct ReceiveResult {
  ArrivalVerdict verdict = ArrivalVerdict::kRejected;
  bool acknowledge = false;
  RobotId robot = 0;
  SubmapHeader routing;  ///< from the frame when it could be read
  std::string reason;    ///< empty when accepted
};

struct ReceiverStats {
  std::size_t frames = 0, accepted = 0, duplicates = 0, stale = 0, rejected = 0;
  std::size_t bytes = 0;
};

class SubmapReceiver {
 public:
  using Sink = std::function<void(ReceivedSubmap&&)>;
  SubmapReceiver(Bookkeeper* bookkeeper, Sink sink, DecodeLimits limits = {});

  /// `claimed` is what the transport says about the frame (e.g. the ROS message
  /// fields); it must match the frame's own routing header.
  ReceiveResult receive(const std::uint8_t* data, std::size_t size, const SubmapHeader* claimed,
                        double now);
  const ReceiverStats& stats() const { return stats_; }
  /// Counters of a checkpoint the server resumed from.
  void restoreStats(const ReceiverStats& stats) { stats_ = stats; }

 private:
  Bookkeeper* bookkeeper_;
  Sink sink_;
  DecodeLimits limits_;
  ReceiverStats stats_;
};

}  // namespace hermes
