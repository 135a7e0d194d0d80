// Server side of exactly-once delivery: checks and decodes an incoming frame,
// asks the bookkeeper whether it is new, hands each accepted submap exactly once
// to the sink (the credibility queue / map manager) and says how to acknowledge.
// Malformed, oversized, wrong-version, unauthenticated or unknown-agent frames
// are rejected with a reason code and text and never disturb other agents.
// Transport-agnostic: the ROS node and the offline runner both call receive().
//
// Order of the checks (admission.h has the policy): frame header and CRC
// (peekFrame) → routing claimed by the transport → with a keyring: robot known,
// tag present, tag valid (nothing unauthenticated goes further) → already
// accepted (replay / resend: acknowledged, not decoded) → the robot's quota
// (refused without ack: the robot resends later) → decode → bookkeeper.
#pragma once

#include <array>
#include <functional>
#include <string>
#include <vector>

#include "hermes/core/delivery.h"
#include "hermes/core/keyring.h"
#include "hermes/core/wire_format.h"
#include "hermes/server/bookkeeper.h"

namespace hermes {

struct ReceivedSubmap {
  RobotId robot = 0;
  Submap submap;
  std::size_t bytes = 0;  ///< frame size as received
  double arrival_time = 0;
};

// ReceiveCode, ReceiveResult: hermes/core/delivery.h (what transports see too).

struct ReceiverStats {
  std::size_t frames = 0, accepted = 0, duplicates = 0, stale = 0, rejected = 0;
  std::size_t bytes = 0;
  std::array<std::size_t, kReceiveCodes> by_code{};  ///< frames per ReceiveCode
  std::size_t count(ReceiveCode c) const { return by_code[static_cast<std::size_t>(c)]; }
};

/// Optional gates in front of the decoder (admission.h).
struct ReceiverGuards {
  /// Non-null: frames must carry a valid tag of a robot in the keyring.
  const Keyring* keyring = nullptr;
  /// Set: asked before decoding a new submap of a known robot; a non-empty
  /// answer refuses it with ReceiveCode::kQuota and that text.
  std::function<std::string(RobotId, std::size_t bytes)> quota;
};

class SubmapReceiver {
 public:
  using Sink = std::function<void(ReceivedSubmap&&)>;
  SubmapReceiver(Bookkeeper* bookkeeper, Sink sink, DecodeLimits limits = {},
                 ReceiverGuards guards = {});

  /// `claimed` is what the transport says about the frame (e.g. the ROS message
  /// fields); it must match the frame's own routing header.
  ReceiveResult receive(const std::uint8_t* data, std::size_t size, const SubmapHeader* claimed,
                        double now);
  const ReceiverStats& stats() const { return stats_; }
  /// Counters of a checkpoint the server resumed from.
  void restoreStats(const ReceiverStats& stats) { stats_ = stats; }

 private:
  /// The tag check; empty when the frame may go on, else why it may not.
  std::string authenticate(const std::uint8_t* data, std::size_t size, const Uuid& agent,
                           ReceiveCode* code) const;
  ReceiveResult& finish(ReceiveResult& r);

  Bookkeeper* bookkeeper_;
  Sink sink_;
  DecodeLimits limits_;
  ReceiverGuards guards_;
  ReceiverStats stats_;
};

}  // namespace hermes
