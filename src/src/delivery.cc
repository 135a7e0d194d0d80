#include "hermes/core/delivery.h"

namespace hermes {

const char* toString(ArrivalVerdict v) {
  switch (v) {
    case ArrivalVerdict::kAccept: return "accept";
    case ArrivalVerdict::kDuplicate: return "duplicate";
    case ArrivalVerdict::kStale: return "stale";
    case ArrivalVerdict::kRejected: return "rejected";
  }
  return "?";
}

const char* toString(ReceiveCode code) {
  switch (code) {
    case ReceiveCode::kAccepted: return "accepted";
    case ReceiveCode::kReplay: return "replay";
    case ReceiveCode::kStale: return "stale";
    case ReceiveCode::kMalformed: return "malformed";
    case ReceiveCode::kRoutingMismatch: return "routing_mismatch";
    case ReceiveCode::kUnknownRobot: return "unknown_robot";
    case ReceiveCode::kMissingTag: return "missing_tag";
    case ReceiveCode::kBadTag: return "bad_tag";
    case ReceiveCode::kQuota: return "quota";
    case ReceiveCode::kRefused: return "refused";
  }
  return "?";
}

}  // namespace hermes
