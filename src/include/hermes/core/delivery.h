// What became of a submap frame at the server, as both ends of exactly-once delivery
// and every transport between them see it: the arrival verdict, the reason code the
// acknowledgement carries (SubmapAck.reason_code has the same numbers), and the
// result a receiver hands back. Plain types, so that transports depend on core only.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "hermes/core/map_types.h"

namespace hermes {

using RobotId = std::uint32_t;

enum class ArrivalVerdict { kAccept, kDuplicate, kStale, kRejected };
const char* toString(ArrivalVerdict v);

enum class ReceiveCode : std::uint8_t {
  kAccepted = 0,
  kReplay = 1,           ///< (session, seq) already accepted: acknowledged again, not applied
  kStale = 2,            ///< a superseded session's late submap: acknowledged, not applied
  kMalformed = 3,        ///< not a readable frame or submap (the text says what, where)
  kRoutingMismatch = 4,  ///< the transport's uuid/session/seq disagree with the frame's
  kUnknownRobot = 5,     ///< authentication on, and no key for the frame's uuid
  kMissingTag = 6,       ///< authentication on, and the frame carries no tag
  kBadTag = 7,           ///< the tag is not the robot's key's for these bytes (forged, altered)
  kQuota = 8,            ///< the robot's queue or byte quota is full: not acknowledged, resend later
  kRefused = 9,          ///< the bookkeeper refused it (unregistered agent, nil uuid)
};
constexpr std::size_t kReceiveCodes = 10;
/// "accepted", "replay", "stale", "malformed", "routing_mismatch", "unknown_robot",
/// "missing_tag", "bad_tag", "quota", "refused".
const char* toString(ReceiveCode code);

struct ReceiveResult {
  ArrivalVerdict verdict = ArrivalVerdict::kRejected;
  ReceiveCode code = ReceiveCode::kMalformed;
  bool acknowledge = false;
  RobotId robot = 0;
  SubmapHeader routing;  ///< from the frame when it could be read
  std::string reason;    ///< empty when accepted
};

}  // namespace hermes
