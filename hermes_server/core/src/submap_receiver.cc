#include "hermes/server/submap_receiver.h"

#include "hermes/core/frame_auth.h"

namespace hermes {

namespace {

ReceiveCode codeOf(ArrivalVerdict v) {
  switch (v) {
    case ArrivalVerdict::kAccept: return ReceiveCode::kAccepted;
    case ArrivalVerdict::kDuplicate: return ReceiveCode::kReplay;
    case ArrivalVerdict::kStale: return ReceiveCode::kStale;
    case ArrivalVerdict::kRejected: return ReceiveCode::kRefused;
  }
  return ReceiveCode::kRefused;
}

std::string describeRouting(const SubmapHeader& h) {
  return "uuid " + toString(h.agent) + ", session " + std::to_string(h.session) + ", seq " +
         std::to_string(h.seq);
}

}  // namespace

SubmapReceiver::SubmapReceiver(Bookkeeper* bookkeeper, Sink sink, DecodeLimits limits,
                               ReceiverGuards guards)
    : bookkeeper_(bookkeeper), sink_(std::move(sink)), limits_(limits), guards_(std::move(guards)) {
  HERMES_CHECK(bookkeeper_ != nullptr, "receiver needs a bookkeeper");
}

std::string SubmapReceiver::authenticate(const std::uint8_t* data, std::size_t size,
                                         const Uuid& agent, ReceiveCode* code) const {
  const Keyring::Entry* entry = guards_.keyring->find(agent);
  if (!entry) {
    *code = ReceiveCode::kUnknownRobot;
    return "auth: no key for agent uuid " + toString(agent) + " (unknown robot)";
  }
  switch (verifyFrameTag(data, size, entry->key)) {
    case TagCheck::kValid: return {};
    case TagCheck::kMissing:
      *code = ReceiveCode::kMissingTag;
      return "auth: frame of robot " + entry->robot + " carries no tag (authentication is on)";
    case TagCheck::kMismatch:
      *code = ReceiveCode::kBadTag;
      return "auth: tag of the frame claiming to be robot " + entry->robot +
             " does not match its key (forged or altered)";
    case TagCheck::kMalformed: break;  // peekFrame passed before: cannot happen
  }
  *code = ReceiveCode::kMalformed;
  return "auth: frame could not be read for the tag check";
}

ReceiveResult& SubmapReceiver::finish(ReceiveResult& r) {
  ++stats_.by_code[static_cast<std::size_t>(r.code)];
  switch (r.code) {
    case ReceiveCode::kAccepted: ++stats_.accepted; break;
    case ReceiveCode::kReplay: ++stats_.duplicates; break;
    case ReceiveCode::kStale: ++stats_.stale; break;
    default: ++stats_.rejected; break;
  }
  return r;
}

ReceiveResult SubmapReceiver::receive(const std::uint8_t* data, std::size_t size,
                                      const SubmapHeader* claimed, double now) {
  ++stats_.frames;
  stats_.bytes += size;
  ReceiveResult r;
  auto reject = [&](ReceiveCode code, std::string why) -> ReceiveResult& {
    r.verdict = ArrivalVerdict::kRejected;
    r.code = code;
    r.acknowledge = false;
    r.reason = std::move(why);
    return finish(r);
  };
  auto decided = [&](const ArrivalDecision& d) -> ReceiveResult& {
    r.verdict = d.verdict;
    r.code = codeOf(d.verdict);
    r.acknowledge = d.acknowledge;
    r.robot = d.robot;
    r.reason = d.reason;
    return finish(r);
  };
  auto header = peekFrame(data, size, limits_);
  if (!header) return reject(ReceiveCode::kMalformed, header.error());
  r.routing = header->routing;
  if (claimed && (claimed->agent != r.routing.agent || claimed->session != r.routing.session ||
                  claimed->seq != r.routing.seq))
    return reject(ReceiveCode::kRoutingMismatch, "frame routing (" + describeRouting(r.routing) +
                                                     ") does not match the message that carried it");
  if (guards_.keyring) {
    ReceiveCode code = ReceiveCode::kMalformed;
    if (std::string why = authenticate(data, size, r.routing.agent, &code); !why.empty())
      return reject(code, why + " [" + describeRouting(r.routing) + "]");
  }
  // Cheap duplicate check before the full decode: a resend (or replay) of
  // something already accepted needs only an ack.
  const auto robot = bookkeeper_->robotOf(r.routing.agent);
  if (robot && bookkeeper_->isDuplicate(*robot, r.routing.session, r.routing.seq)) {
    SubmapArrival probe;
    probe.header = r.routing;
    probe.bytes = size;
    decided(bookkeeper_->onArrival(probe, now));
    r.reason = "replay: " + r.reason + "; acknowledged again, not applied";
    return r;
  }
  if (robot && guards_.quota) {
    if (std::string why = guards_.quota(*robot, size); !why.empty()) {
      reject(ReceiveCode::kQuota, "quota: " + bookkeeper_->describe(*robot) + " has " + why +
                                      "; not acknowledged, resend later [" +
                                      describeRouting(r.routing) + "]");
      r.robot = *robot;
      return r;
    }
  }
  auto submap = decodeSubmap(data, size, limits_);
  if (!submap) return reject(ReceiveCode::kMalformed, submap.error());
  const ArrivalDecision d = bookkeeper_->onArrival(SubmapArrival::of(*submap, size), now);
  decided(d);
  if (d.verdict == ArrivalVerdict::kAccept) {
    ReceivedSubmap out{d.robot, std::move(*submap), size, now};
    sink_(std::move(out));
    if (Status s = bookkeeper_->markApplied(d.robot, r.routing.session, r.routing.seq); !s)
      r.reason = s.error();
  }
  return r;
}

}  // namespace hermes
