#include "hermes/agent/map_buffer.h"

#include <limits>

#include "hermes/core/crc32.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>

namespace hermes::agent {
namespace {

constexpr std::uint32_t kMagic = 0x31505348;  // "HSP1"
constexpr std::uint8_t kData = 1, kAck = 2;
constexpr std::size_t kHeader = 4 + 4 + 4 + 8 + 4 + 4;
constexpr std::size_t kMaxRecord = std::size_t{1} << 30;

template <class T>
void put(std::vector<std::uint8_t>& b, T v) {
  std::uint8_t raw[sizeof(T)];
  std::memcpy(raw, &v, sizeof(T));  // little-endian hosts only (x86/ARM)
  b.insert(b.end(), raw, raw + sizeof(T));
}
template <class T>
T get(const std::uint8_t* p) {
  T v;
  std::memcpy(&v, p, sizeof(T));
  return v;
}

std::vector<std::uint8_t> makeRecord(std::uint8_t type, std::uint32_t session, std::uint64_t seq,
                                     const std::vector<std::uint8_t>& payload) {
  std::vector<std::uint8_t> r;
  r.reserve(kHeader + payload.size());
  put(r, kMagic);
  r.push_back(type);
  r.insert(r.end(), {0, 0, 0});
  put(r, session);
  put(r, seq);
  put(r, static_cast<std::uint32_t>(payload.size()));
  std::uint32_t crc = crc32(r.data(), r.size());
  crc = crc32(payload.data(), payload.size(), crc);
  put(r, crc);
  r.insert(r.end(), payload.begin(), payload.end());
  return r;
}

Status writeAll(int fd, const std::vector<std::uint8_t>& b, const std::string& path) {
  std::size_t off = 0;
  while (off < b.size()) {
    const ssize_t n = ::write(fd, b.data() + off, b.size() - off);
    if (n < 0) {
      if (errno == EINTR) continue;
      return Error{"map buffer: write to '" + path + "' failed: " + std::strerror(errno)};
    }
    off += static_cast<std::size_t>(n);
  }
  return Status::Ok();
}

}  // namespace

Status MapBufferParams::read(const Config& c) {
  if (Status s = c.get("uplink.buffer.dir", &dir); !s) return s;
  if (Status s = c.get("uplink.buffer.max_mbytes", &max_mbytes); !s) return s;
  if (Status s = c.get("uplink.buffer.fsync", &fsync); !s) return s;
  if (Status s = c.get("uplink.buffer.resend_timeout_s", &resend_timeout_s); !s) return s;
  return validate();
}

Status MapBufferParams::validate() const {
  if (dir.empty()) return Error{"uplink.buffer.dir must name a spool directory"};
  if (!(max_mbytes > 0)) return Error{"uplink.buffer.max_mbytes must be > 0"};
  if (!(resend_timeout_s > 0)) return Error{"uplink.buffer.resend_timeout_s must be > 0"};
  return Status::Ok();
}

void MapBufferParams::write(ConfigWriter& w) const {
  w.set("uplink.buffer.dir", dir);
  w.set("uplink.buffer.max_mbytes", max_mbytes);
  w.set("uplink.buffer.fsync", fsync);
  w.set("uplink.buffer.resend_timeout_s", resend_timeout_s);
}

MapBuffer::MapBuffer(MapBufferParams p) : p_(std::move(p)) {}

MapBuffer::MapBuffer(MapBuffer&& o) noexcept
    : p_(std::move(o.p_)),
      pending_(std::move(o.pending_)),
      pending_bytes_(o.pending_bytes_),
      file_bytes_(o.file_bytes_),
      torn_bytes_(o.torn_bytes_),
      fd_(o.fd_) {
  o.fd_ = -1;  // the moved-from buffer must not close our file
}

MapBuffer& MapBuffer::operator=(MapBuffer&& o) noexcept {
  if (this != &o) {
    if (fd_ >= 0) ::close(fd_);
    p_ = std::move(o.p_);
    pending_ = std::move(o.pending_);
    pending_bytes_ = o.pending_bytes_;
    file_bytes_ = o.file_bytes_;
    torn_bytes_ = o.torn_bytes_;
    fd_ = o.fd_;
    o.fd_ = -1;
  }
  return *this;
}

MapBuffer::~MapBuffer() {
  if (fd_ >= 0) ::close(fd_);
}

std::string MapBuffer::spoolPath() const { return p_.dir + "/spool.bin"; }

Expected<MapBuffer> MapBuffer::open(const MapBufferParams& params) {
  if (Status s = params.validate(); !s) return Error{s.error()};
  std::error_code ec;
  std::filesystem::create_directories(params.dir, ec);
  if (ec) return Error{"map buffer: cannot create spool directory '" + params.dir + "': " + ec.message()};
  MapBuffer b(params);
  if (Status s = b.replay(); !s) return Error{s.error()};
  b.fd_ = ::open(b.spoolPath().c_str(), O_WRONLY | O_APPEND | O_CREAT | O_CLOEXEC, 0644);
  if (b.fd_ < 0)
    return Error{"map buffer: cannot open '" + b.spoolPath() + "': " + std::strerror(errno)};
  return b;
}

Status MapBuffer::replay() {
  const std::string path = spoolPath();
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::Ok();  // fresh spool
  std::vector<std::uint8_t> data((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::size_t off = 0;
  while (off + kHeader <= data.size()) {
    const std::uint8_t* h = data.data() + off;
    const std::uint32_t len = get<std::uint32_t>(h + 20);
    if (get<std::uint32_t>(h) != kMagic || len > kMaxRecord || off + kHeader + len > data.size())
      break;
    std::uint32_t crc = crc32(h, 24);
    crc = crc32(h + kHeader, len, crc);
    if (crc != get<std::uint32_t>(h + 24)) break;
    const std::uint8_t type = h[4];
    const auto key = std::make_pair(get<std::uint32_t>(h + 8), get<std::uint64_t>(h + 12));
    if (type == kData && !pending_.count(key)) {
      BufferedSubmap s;
      s.session = key.first;
      s.seq = key.second;
      s.frame.assign(h + kHeader, h + kHeader + len);
      pending_bytes_ += len;
      pending_.emplace(key, std::move(s));
    } else if (type == kAck) {
      auto it = pending_.find(key);
      if (it != pending_.end()) {
        pending_bytes_ -= it->second.frame.size();
        pending_.erase(it);
      }
    }
    off += kHeader + len;
  }
  if (off < data.size()) {
    // A torn or corrupt tail: cut it off so new records follow valid ones.
    torn_bytes_ = data.size() - off;
    if (::truncate(path.c_str(), static_cast<off_t>(off)) != 0)
      return Error{"map buffer: cannot truncate torn tail of '" + path + "': " + std::strerror(errno)};
  }
  file_bytes_ = off;
  return Status::Ok();
}

Status MapBuffer::append(std::uint8_t type, std::uint32_t session, std::uint64_t seq,
                         const std::vector<std::uint8_t>& payload) {
  const auto rec = makeRecord(type, session, seq, payload);
  if (Status s = writeAll(fd_, rec, spoolPath()); !s) return s;
  if (p_.fsync && ::fsync(fd_) != 0)
    return Error{"map buffer: fsync of '" + spoolPath() + "' failed: " + std::strerror(errno)};
  file_bytes_ += rec.size();
  return Status::Ok();
}

Status MapBuffer::push(std::uint32_t session, std::uint64_t seq, std::vector<std::uint8_t> frame) {
  const auto key = std::make_pair(session, seq);
  if (pending_.count(key))
    return Error{"map buffer: submap (session " + std::to_string(session) + ", seq " +
                 std::to_string(seq) + ") is already buffered"};
  const double cap = p_.max_mbytes * 1e6;
  if (static_cast<double>(pending_bytes_ + frame.size()) > cap)
    return Error{"map buffer full: " + std::to_string(pending_bytes_) + " bytes pending, " +
                 std::to_string(frame.size()) + " more would exceed the cap of " +
                 std::to_string(static_cast<long long>(cap)) + " bytes"};
  if (Status s = append(kData, session, seq, frame); !s) return s;
  BufferedSubmap b;
  b.session = session;
  b.seq = seq;
  b.frame = std::move(frame);
  pending_bytes_ += b.frame.size();
  pending_.emplace(key, std::move(b));
  return Status::Ok();
}

Status MapBuffer::ack(std::uint32_t session, std::uint64_t seq) {
  auto it = pending_.find({session, seq});
  if (it == pending_.end()) return Status::Ok();
  if (Status s = append(kAck, session, seq, {}); !s) return s;
  pending_bytes_ -= it->second.frame.size();
  pending_.erase(it);
  if (file_bytes_ > 2 * (pending_bytes_ + pending_.size() * kHeader) + (1 << 20)) return compact();
  return Status::Ok();
}

Status MapBuffer::compact() {
  const std::string tmp = spoolPath() + ".tmp";
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return Error{"map buffer: cannot create '" + tmp + "': " + std::strerror(errno)};
  std::size_t bytes = 0;
  for (const auto& [key, s] : pending_) {
    const auto rec = makeRecord(kData, s.session, s.seq, s.frame);
    if (Status st = writeAll(fd, rec, tmp); !st) {
      ::close(fd);
      return st;
    }
    bytes += rec.size();
  }
  if ((p_.fsync && ::fsync(fd) != 0) || ::close(fd) != 0)
    return Error{"map buffer: cannot flush '" + tmp + "': " + std::strerror(errno)};
  if (std::rename(tmp.c_str(), spoolPath().c_str()) != 0)
    return Error{"map buffer: cannot replace '" + spoolPath() + "': " + std::strerror(errno)};
  ::close(fd_);
  fd_ = ::open(spoolPath().c_str(), O_WRONLY | O_APPEND | O_CLOEXEC);
  if (fd_ < 0) return Error{"map buffer: cannot reopen '" + spoolPath() + "': " + std::strerror(errno)};
  file_bytes_ = bytes;
  return Status::Ok();
}

BufferedSubmap* MapBuffer::nextToSend(double now) {
  for (auto& [key, s] : pending_)
    if (s.last_sent < 0 ||
        now - s.last_sent >= p_.resend_timeout_s * double(1 << std::clamp(s.sends - 1, 0, 3)))
      return &s;
  return nullptr;
}

void MapBuffer::markSent(std::uint32_t session, std::uint64_t seq, double now) {
  auto it = pending_.find({session, seq});
  if (it == pending_.end()) return;
  it->second.last_sent = now;
  ++it->second.sends;
}

void MapBuffer::hold(std::uint32_t session, std::uint64_t seq) {
  auto it = pending_.find({session, seq});
  if (it != pending_.end()) it->second.last_sent = std::numeric_limits<double>::infinity();
}

void MapBuffer::resetSendTimes() {
  for (auto& [key, s] : pending_) s.last_sent = -1.0;
}

Expected<std::uint32_t> MapBuffer::newSession() {
  const std::string path = p_.dir + "/session";
  std::uint32_t last = 0;
  bool have = false;
  {
    std::ifstream in(path);
    if (in && (in >> last)) have = true;
  }
  // Sessions must also exceed anything still pending in the spool.
  for (const auto& [key, s] : pending_) {
    if (!have || key.first > last) last = key.first;
    have = true;
  }
  const std::uint32_t next = have ? last + 1 : 0;
  if (Status s = writeSession(next); !s) return Error{s.error()};
  return next;
}

Status MapBuffer::writeSession(std::uint32_t session) {
  const std::string path = p_.dir + "/session";
  const std::string tmp = path + ".tmp";
  {
    std::ofstream out(tmp, std::ios::trunc);
    out << session << "\n";
    if (!out.flush()) return Error{"map buffer: cannot write '" + tmp + "'"};
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0)
    return Error{"map buffer: cannot write '" + path + "': " + std::strerror(errno)};
  return Status::Ok();
}

Expected<std::size_t> MapBuffer::discardPending() {
  const std::size_t dropped = pending_.size();
  if (dropped == 0) return dropped;
  // The counter must stay >= every dropped session (newSession() looked at them too).
  std::uint32_t highest = pending_.rbegin()->first.first;
  {
    std::ifstream in(p_.dir + "/session");
    std::uint32_t stored = 0;
    if (in && (in >> stored)) highest = std::max(highest, stored);
  }
  if (Status s = writeSession(highest); !s) return Error{s.error()};
  pending_.clear();
  pending_bytes_ = 0;
  if (Status s = compact(); !s) return Error{s.error()};
  return dropped;
}

}  // namespace hermes::agent
