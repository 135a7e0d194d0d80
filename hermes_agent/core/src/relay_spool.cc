#include "hermes/agent/relay_spool.h"

#include <filesystem>

#include "hermes/core/wire_format.h"

namespace hermes::agent {
namespace fs = std::filesystem;

Status checkRobotName(const std::string& name) {
  if (name.empty() || name == "." || name == "..")
    return Error{"robot name '" + name + "' is not usable as a folder name"};
  for (char ch : name)
    if (!(std::isalnum(static_cast<unsigned char>(ch)) || ch == '_' || ch == '-' || ch == '.'))
      return Error{"robot name '" + name + "' holds '" + std::string(1, ch) +
                   "' (allowed: letters, digits, _ - .)"};
  return Status::Ok();
}

Expected<std::unique_ptr<RelaySpool>> RelaySpool::open(const std::string& dir,
                                                       const UplinkParams& uplink,
                                                       Forward forward) {
  if (dir.empty()) return Error{"relay spool: no folder given"};
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return Error{"relay spool " + dir + ": " + ec.message()};
  UplinkParams p = uplink;
  p.auth.enabled = false;  // frames keep the origin's own tag
  std::unique_ptr<RelaySpool> spool(new RelaySpool(dir, p, std::move(forward)));
  std::vector<std::string> names;
  for (const fs::directory_entry& e : fs::directory_iterator(dir, ec))
    if (e.is_directory()) names.push_back(e.path().filename().string());
  if (ec) return Error{"relay spool " + dir + ": " + ec.message()};
  for (const std::string& name : names) {  // a restarted relay forwards what it held
    if (!checkRobotName(name)) continue;
    auto origin = spool->originFor(name);
    if (!origin) return Error{origin.error()};
  }
  return spool;
}

Expected<RelaySpool::Origin*> RelaySpool::originFor(const std::string& name) {
  if (auto it = origins_.find(name); it != origins_.end()) return &it->second;
  if (Status s = checkRobotName(name); !s) return Error{"relay spool: " + s.error()};
  UplinkParams p = uplink_;
  p.buffer.dir = (fs::path(dir_) / name).string();
  auto sender = UplinkSender::create(
      p, [this, name](std::uint32_t session, std::uint64_t seq, const std::vector<std::uint8_t>& f) {
        forward_(name, session, seq, f);
      });
  if (!sender) return Error{"relay spool of " + name + ": " + sender.error()};
  Origin& o = origins_[name];
  o.sender = std::make_unique<UplinkSender>(std::move(*sender));
  return &o;
}

Expected<RelaySpool::Offer> RelaySpool::offer(const std::string& origin, std::uint32_t session,
                                              std::uint64_t seq, std::vector<std::uint8_t> frame,
                                              double now) {
  auto o = originFor(origin);
  if (!o) return Error{o.error()};
  Origin& org = **o;
  const auto key = std::make_pair(session, seq);
  org.stats.bytes_received += static_cast<double>(frame.size());
  const bool held = org.sender->buffer().find(session, seq) != nullptr;
  if (held || org.acked.count(key)) {
    ++org.stats.duplicates;
    org.evidence.onFrame(frame, now, /*duplicate=*/true);
    return held ? Offer::kAlreadyHeld : Offer::kAlreadyAcked;
  }
  auto header = peekFrame(frame.data(), frame.size());
  if (!header)
    return Error{"relay: submap " + std::to_string(session) + "/" + std::to_string(seq) + " of " +
                 origin + " refused: " + header.error()};
  if (header->routing.session != session || header->routing.seq != seq)
    return Error{"relay: submap of " + origin + " claims " + std::to_string(session) + "/" +
                 std::to_string(seq) + " but its frame says " +
                 std::to_string(header->routing.session) + "/" +
                 std::to_string(header->routing.seq)};
  org.evidence.onFrame(frame, now, /*duplicate=*/false);
  if (Status s = org.sender->submit(session, seq, std::move(frame), now); !s)
    return Error{"relay: submap of " + origin + " not stored: " + s.error()};
  ++org.stats.stored;
  return Offer::kStored;
}

bool RelaySpool::onServerAck(const std::string& origin, std::uint32_t session, std::uint64_t seq,
                             double now) {
  auto it = origins_.find(origin);
  if (it == origins_.end()) return false;
  Origin& o = it->second;
  const bool held = o.sender->buffer().find(session, seq) != nullptr;
  o.acked.insert({session, seq});
  (void)o.sender->onAck(session, seq, now);  // a failed ACK record is replayed as pending: resent, deduplicated
  if (held) ++o.stats.server_acked;
  return held;
}

void RelaySpool::poll(double now) {
  for (auto& [name, o] : origins_) o.sender->poll(now);
}

void RelaySpool::onReconnect() {
  for (auto& [name, o] : origins_) o.sender->onReconnect();
}

std::vector<std::string> RelaySpool::origins() const {
  std::vector<std::string> out;
  for (const auto& [name, o] : origins_) out.push_back(name);
  return out;
}

std::size_t RelaySpool::pendingBytes() const {
  std::size_t n = 0;
  for (const auto& [name, o] : origins_) n += o.sender->buffer().pendingBytes();
  return n;
}

std::size_t RelaySpool::pendingBytes(const std::string& origin) const {
  auto it = origins_.find(origin);
  return it == origins_.end() ? 0 : it->second.sender->buffer().pendingBytes();
}

std::size_t RelaySpool::pendingCount(const std::string& origin) const {
  auto it = origins_.find(origin);
  return it == origins_.end() ? 0 : it->second.sender->buffer().pendingCount();
}

RelayStream RelaySpool::stream(const std::string& origin, double now) const {
  auto it = origins_.find(origin);
  return it == origins_.end() ? RelayStream{} : it->second.evidence.stream(now, false);
}

const RelaySpool::OriginStats* RelaySpool::stats(const std::string& origin) const {
  auto it = origins_.find(origin);
  return it == origins_.end() ? nullptr : &it->second.stats;
}

}  // namespace hermes::agent
