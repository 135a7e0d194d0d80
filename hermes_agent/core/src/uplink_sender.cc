#include "hermes/agent/uplink_sender.h"

#include "hermes/core/keyring.h"
#include "hermes/core/wire_format.h"

namespace hermes::agent {

std::string UplinkAuthParams::keyFileFor(const std::string& robot) const {
  std::string path = key_file;
  for (std::size_t at = path.find("{robot}"); at != std::string::npos;
       at = path.find("{robot}", at + robot.size()))
    path.replace(at, 7, robot);
  return expandHome(path);
}

Status UplinkParams::read(const Config& c) {
  if (Status s = buffer.read(c); !s) return s;
  if (Status s = monitor.read(c); !s) return s;
  for (Status s : {c.get("uplink.max_in_flight_mbytes", &max_in_flight_mbytes),
                   c.get("uplink.auth.enabled", &auth.enabled),
                   c.get("uplink.auth.key_file", &auth.key_file)})
    if (!s) return s;
  return validate();
}

Status UplinkParams::validate() const {
  if (Status s = buffer.validate(); !s) return s;
  if (Status s = monitor.validate(); !s) return s;
  if (!(max_in_flight_mbytes > 0)) return Error{"uplink.max_in_flight_mbytes must be > 0"};
  if (auth.enabled && auth.key_file.empty())
    return Error{"uplink.auth.key_file must name the robot's key file when uplink.auth.enabled"};
  return Status::Ok();
}

void UplinkParams::write(ConfigWriter& w) const {
  buffer.write(w);
  monitor.write(w);
  w.set("uplink.max_in_flight_mbytes", max_in_flight_mbytes);
  w.set("uplink.auth.enabled", auth.enabled);
  w.set("uplink.auth.key_file", auth.key_file);
}

UplinkSender::UplinkSender(UplinkParams p, MapBuffer buffer, Transport transport,
                           std::optional<FrameKey> key)
    : p_(std::move(p)),
      key_(key),
      buffer_(std::move(buffer)),
      monitor_(p_.monitor),
      transport_(std::move(transport)) {}

Expected<UplinkSender> UplinkSender::create(const UplinkParams& p, Transport transport,
                                            const std::string& robot) {
  if (Status s = p.validate(); !s) return Error{s.error()};
  std::optional<FrameKey> key;
  if (p.auth.enabled) {
    auto read = readKeyFile(p.auth.keyFileFor(robot));
    if (!read) return Error{read.error() + " (uplink.auth.key_file)"};
    key = *read;
  }
  auto buffer = MapBuffer::open(p.buffer);
  if (!buffer) return Error{buffer.error()};
  return UplinkSender(p, std::move(*buffer), std::move(transport), key);
}

std::size_t UplinkSender::wireBytes(const std::vector<std::uint8_t>& frame) const {
  if (!key_) return frame.size();
  auto h = peekFrame(frame.data(), frame.size());
  return h ? kWireFixedBytes + h->body_bytes + kWireTagBytes : frame.size();
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
    const std::size_t bytes = wireBytes(next->frame);
    if (in_flight > 0 && static_cast<double>(in_flight + bytes) > cap) return;
    std::optional<std::vector<std::uint8_t>> tagged;
    if (key_) {
      // Only a spooled frame damaged on disk cannot be tagged: it goes out as it
      // is and the server's answer (malformed) names the problem.
      auto signed_frame = signFrame(next->frame, *key_);
      if (signed_frame)
        tagged = std::move(*signed_frame);
      else
        ++stats_.untagged;
    }
    const std::uint64_t id = next_send_id_++;
    send_ids_[key] = id;
    in_flight_[key] = bytes;
    monitor_.onSend(id, bytes, now);
    buffer_.markSent(next->session, next->seq, now);
    ++stats_.sends;
    stats_.bytes_sent += bytes;
    transport_(next->session, next->seq, tagged ? *tagged : next->frame);
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
  if (auto it = handed_.find(key); it != handed_.end()) {
    handed_bytes_ -= it->second;
    handed_.erase(it);
  }
  Status s = buffer_.ack(session, seq);
  poll(now);
  return s;
}

void UplinkSender::onHandedOver(std::uint32_t session, std::uint64_t seq, double now) {
  const auto key = std::make_pair(session, seq);
  if (auto it = send_ids_.find(key); it != send_ids_.end()) {
    monitor_.onAck(it->second, now);
    send_ids_.erase(it);
  }
  in_flight_.erase(key);
  const BufferedSubmap* b = buffer_.find(session, seq);
  if (b && handed_.count(key) == 0) {
    handed_[key] = b->frame.size();
    handed_bytes_ += b->frame.size();
    buffer_.hold(session, seq);
  }
  poll(now);
}

void UplinkSender::onReconnect() {
  for (const auto& [key, id] : send_ids_) monitor_.onGiveUp(id);
  send_ids_.clear();
  in_flight_.clear();
  handed_.clear();
  handed_bytes_ = 0;
  buffer_.resetSendTimes();
}

}  // namespace hermes::agent
