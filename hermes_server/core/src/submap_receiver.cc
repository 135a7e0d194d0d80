#include "hermes/server/submap_receiver.h"

namespace hermes {

SubmapReceiver::SubmapReceiver(Bookkeeper* bookkeeper, Sink sink, DecodeLimits limits)
    : bookkeeper_(bookkeeper), sink_(std::move(sink)), limits_(limits) {
  HERMES_CHECK(bookkeeper_ != nullptr, "receiver needs a bookkeeper");
}

ReceiveResult SubmapReceiver::receive(const std::uint8_t* data, std::size_t size,
                                      const SubmapHeader* claimed, double now) {
  ++stats_.frames;
  stats_.bytes += size;
  ReceiveResult r;
  auto reject = [&](std::string why) {
    ++stats_.rejected;
    r.verdict = ArrivalVerdict::kRejected;
    r.acknowledge = false;
    r.reason = std::move(why);
    return r;
  };
  auto header = peekFrame(data, size, limits_);
  if (!header) return reject(header.error());
  r.routing = header->routing;
  if (claimed && (claimed->agent != r.routing.agent || claimed->session != r.routing.session ||
                  claimed->seq != r.routing.seq))
    return reject("frame routing (uuid " + toString(r.routing.agent) + ", session " +
                  std::to_string(r.routing.session) + ", seq " + std::to_string(r.routing.seq) +
                  ") does not match the message that carried it");
  // Cheap duplicate check before the full decode: a resend of something already
  // accepted needs only an ack.
  if (auto robot = bookkeeper_->robotOf(r.routing.agent)) {
    SubmapArrival probe;
    probe.header = r.routing;
    probe.bytes = size;
    if (bookkeeper_->isDuplicate(*robot, r.routing.session, r.routing.seq)) {
      const ArrivalDecision d = bookkeeper_->onArrival(probe, now);
      ++stats_.duplicates;
      r.verdict = d.verdict;
      r.acknowledge = d.acknowledge;
      r.robot = d.robot;
      r.reason = d.reason;
      return r;
    }
  }
  auto submap = decodeSubmap(data, size, limits_);
  if (!submap) return reject(submap.error());
  const ArrivalDecision d = bookkeeper_->onArrival(SubmapArrival::of(*submap, size), now);
  r.verdict = d.verdict;
  r.acknowledge = d.acknowledge;
  r.robot = d.robot;
  r.reason = d.reason;
  switch (d.verdict) {
    case ArrivalVerdict::kAccept: {
      ++stats_.accepted;
      ReceivedSubmap out{d.robot, std::move(*submap), size, now};
      sink_(std::move(out));
      if (Status s = bookkeeper_->markApplied(d.robot, r.routing.session, r.routing.seq); !s)
        r.reason = s.error();
      break;
    }
    case ArrivalVerdict::kDuplicate: ++stats_.duplicates; break;
    case ArrivalVerdict::kStale: ++stats_.stale; break;
    case ArrivalVerdict::kRejected: ++stats_.rejected; break;
  }
  return r;
}

}  // namespace hermes
