#include "hermes/agent/uplink_sender.h"

namespace hermes::agent {

Status UplinkParams::read(const Config& c) {
  if (Status s = buffer.read(c); !s) return s;
  if (Status s = monitor.read(c); !s) return s;
  if (Status s = c.get("uplink.max_in_flight_mbytes", &max_in_flight_mbytes); !s) return s;
  return validate();
}

Status UplinkParams::validate() const {
  if (Status s = buffer.validate(); !s) return s;
  if (Status s = monitor.validate(); !s) return s;
  if (!(max_in_flight_mbytes > 0)) return Error{"uplink.max_in_flight_mbytes must be > 0"};
  return Status::Ok();
}

void UplinkParams::write(ConfigWriter& w) const {
  buffer.write(w);
  monitor.write(w);
  w.set("uplink.max_in_flight_mbytes", max_in_flight_mbytes);
}

UplinkSender::UplinkSender(UplinkParams p, MapBuffer buffer, Transport transport)
    : p_(std::move(p)), buffer_(std::move(buffer)), monitor_(p_.monitor), transport_(std::move(transport)) {}

Expected<UplinkSender> UplinkSender::create(const UplinkParams& p, Transport transport) {
  if (Status s = p.validate(); !s) return Error{s.error()};
  auto buffer = MapBuffer::open(p.buffer);
  if (!buffer) return Error{buffer.error()};
  return UplinkSender(p, std::move(*buffer), std::move(transport));
}

Status UplinkSender::submit(std::uint32_t session, std::uint64_t seq,
                            std::vector<std::uint8_t> frame, double now) {
  Status s = buffer_.push(session, seq, std::move(frame));
  if (!s) {
    ++stats_.refused;
    return s;
  }
  ++stats_.submitted;
  poll(now);
  return Status::Ok();
}

void UplinkSender::poll(double now) {
  const double cap = p_.max_in_flight_mbytes * 1e6;
  while (true) {
    std::size_t in_flight = 0;
    for (const auto& [k, b] : in_flight_) in_flight += b;
    BufferedSubmap* next = buffer_.nextToSend(now);
    if (!next) return;
    const auto key = std::make_pair(next->session, next->seq);
    // A resend replaces the earlier attempt, which is presumed lost -- unless the
    // link may simply still be busy with it: at the estimated rate, everything in
    // flight up to and including it needs in_flight / rate seconds, and resending
    // into a slow link only adds to the congestion.
    if (auto it = in_flight_.find(key); it != in_flight_.end()) {
      const double rate = monitor_.estimate(now);
      const double busy_s = rate > 0 ? static_cast<double>(in_flight) / rate : 0.0;
      if (!monitor_.outage(now) && now - next->last_sent < p_.buffer.resend_timeout_s + busy_s)
        return;
    }
    if (auto it = in_flight_.find(key); it != in_flight_.end()) {
      in_flight -= it->second;
      monitor_.onGiveUp(send_ids_[key]);
      in_flight_.erase(it);
      ++stats_.resends;
    }
    if (in_flight > 0 && static_cast<double>(in_flight + next->frame.size()) > cap) return;
    const std::uint64_t id = next_send_id_++;
    send_ids_[key] = id;
    in_flight_[key] = next->frame.size();
    monitor_.onSend(id, next->frame.size(), now);
    buffer_.markSent(next->session, next->seq, now);
    ++stats_.sends;
    stats_.bytes_sent += next->frame.size();
    transport_(next->session, next->seq, next->frame);
  }
}

Status UplinkSender::onAck(std::uint32_t session, std::uint64_t seq, double now) {
  const auto key = std::make_pair(session, seq);
  if (auto it = send_ids_.find(key); it != send_ids_.end()) {
    monitor_.onAck(it->second, now);
    send_ids_.erase(it);
    ++stats_.acked;
  }
  in_flight_.erase(key);
  Status s = buffer_.ack(session, seq);
  poll(now);
  return s;
}

void UplinkSender::onReconnect() {
  for (const auto& [key, id] : send_ids_) monitor_.onGiveUp(id);
  send_ids_.clear();
  in_flight_.clear();
  buffer_.resetSendTimes();
}

}  // namespace hermes::agent
