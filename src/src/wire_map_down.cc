#include <cmath>
#include <cstring>
#include <set>
#include <string>

#include "hermes/core/crc32.h"
#include "hermes/core/map_down.h"
#include "wire_internal.h"

namespace hermes {
namespace {

using wire::bitsDouble;
using wire::doubleBits;
using wire::getLE;
using wire::putLE;

constexpr std::uint8_t kPacketMagic[4] = {'H', 'M', 'D', 'N'};
constexpr std::uint8_t kAckMagic[4] = {'H', 'M', 'D', 'A'};
constexpr std::size_t kAckBytes = 4 + 16 + 8 + 8 + 4;
// Least bytes a keyframe / landmark can take (varints count 1): the decoder
// checks counts against what is left before it allocates.
constexpr std::size_t kMinKeyframeBytes = 3 + 8 + 7 * 8 + 1;
constexpr std::size_t kMinLandmarkBytes = 3 + 3 * 4 + 32;

bool finite(const Vec3& v) { return v.allFinite(); }
bool finite(const SE3& T) {
  return T.translation().allFinite() && T.quat().coeffs().allFinite() &&
         std::abs(T.quat().norm() - 1.0) < 1e-6;
}

class Writer {
 public:
  void bytes(const void* p, std::size_t n) {
    const auto* b = static_cast<const std::uint8_t*>(p);
    out.insert(out.end(), b, b + n);
  }
  void le(std::uint64_t v, int n) {
    std::uint8_t b[8];
    putLE(b, v, n);
    bytes(b, static_cast<std::size_t>(n));
  }
  void f64(double d) { le(doubleBits(d), 8); }
  void f32(float f) {
    std::uint32_t u;
    std::memcpy(&u, &f, 4);
    le(u, 4);
  }
  void varint(std::uint64_t v) {
    std::uint8_t b[10];
    bytes(b, wire::putVarint(v, b));
  }
  void pose(const SE3& T) {
    const Quat& q = T.quat();
    for (double c : {q.w(), q.x(), q.y(), q.z()}) f64(c);
    for (int i = 0; i < 3; ++i) f64(T.translation()[i]);
  }
  void key(const KeyframeKey& k) {
    varint(k.agent);
    varint(k.session);
    varint(k.id);
  }
  std::vector<std::uint8_t> out;
};

class Reader {
 public:
  Reader(const std::uint8_t* d, std::size_t n, const std::string& origin)
      : d_(d), n_(n), origin_(origin) {}
  std::size_t left() const { return n_ - at_; }
  void need(std::size_t k, const char* what) const {
    if (left() < k)
      throw wire::DecodeError(origin_ + ": truncated at byte " + std::to_string(at_) + " (" + what +
                              ")");
  }
  std::uint64_t le(int k, const char* what) {
    need(static_cast<std::size_t>(k), what);
    const std::uint64_t v = getLE(d_ + at_, k);
    at_ += static_cast<std::size_t>(k);
    return v;
  }
  double f64(const char* what) { return bitsDouble(le(8, what)); }
  float f32(const char* what) {
    const std::uint32_t u = static_cast<std::uint32_t>(le(4, what));
    float f;
    std::memcpy(&f, &u, 4);
    return f;
  }
  std::uint64_t varint(const char* what) {
    std::uint64_t v = 0;
    for (int shift = 0; shift < 64; shift += 7) {
      const std::uint8_t b = static_cast<std::uint8_t>(le(1, what));
      v |= std::uint64_t{b & 0x7Fu} << shift;
      if (!(b & 0x80)) return v;
    }
    throw wire::DecodeError(origin_ + ": varint too long at byte " + std::to_string(at_) + " (" +
                            what + ")");
  }
  std::uint32_t varint32(const char* what) {
    const std::uint64_t v = varint(what);
    if (v > 0xFFFFFFFFu)
      throw wire::DecodeError(origin_ + ": " + what + " out of range at byte " + std::to_string(at_));
    return static_cast<std::uint32_t>(v);
  }
  SE3 pose(const char* what) {
    double c[7];
    for (double& v : c) v = f64(what);
    return SE3::fromUnitQuat(Quat(c[0], c[1], c[2], c[3]), Vec3(c[4], c[5], c[6]));
  }
  KeyframeKey key(const char* what) {
    KeyframeKey k;
    k.agent = varint32(what);
    k.session = varint32(what);
    k.id = varint(what);
    return k;
  }
  void bytes(void* p, std::size_t k, const char* what) {
    need(k, what);
    std::memcpy(p, d_ + at_, k);
    at_ += k;
  }
  /// A count of elements of at least `min_bytes` each that the bytes left can hold.
  std::size_t count(std::size_t min_bytes, const char* what) {
    const std::uint64_t c = varint(what);
    if (c > left() / min_bytes)
      throw wire::DecodeError(origin_ + ": " + what + " count " + std::to_string(c) +
                              " exceeds the " + std::to_string(left()) + " bytes left");
    return static_cast<std::size_t>(c);
  }

 private:
  const std::uint8_t* d_;
  std::size_t n_, at_ = 0;
  const std::string& origin_;
};

void sealCrc(std::vector<std::uint8_t>* out) {
  std::uint8_t b[4];
  putLE(b, crc32(out->data(), out->size()), 4);
  out->insert(out->end(), b, b + 4);
}

Status checkFrame(const std::uint8_t* data, std::size_t size, const std::uint8_t magic[4],
                  std::size_t min_size, const std::string& origin) {
  const std::string name(reinterpret_cast<const char*>(magic), 4);
  if (data == nullptr || size < 4 || std::memcmp(data, magic, 4) != 0)
    return Error{origin + ": not a " + name + " frame (magic)"};
  if (size < min_size)
    return Error{origin + ": " + std::to_string(size) + " bytes, too short for a " + name + " frame"};
  const std::uint32_t stored = static_cast<std::uint32_t>(getLE(data + size - 4, 4));
  if (crc32(data, size - 4) != stored) return Error{origin + ": CRC mismatch (corrupted frame)"};
  return Status::Ok();
}

}  // namespace

Status MapDownPacket::validate() const {
  if (seq == 0) return Error{"map_down: seq 0 (packets are numbered from 1)"};
  if (!finite(T_W_O)) return Error{"map_down: T_W_O not a finite rigid transform"};
  std::set<KeyframeKey> keys;
  for (std::size_t i = 0; i < keyframes.size(); ++i) {
    const BorrowedKeyframe& k = keyframes[i];
    const std::string at = "map_down: keyframe " + std::to_string(i);
    if (!finite(k.T_O_C) || !std::isfinite(k.stamp)) return Error{at + ": pose or stamp not finite"};
    if (!keys.insert(k.origin).second) return Error{at + ": origin key sent twice"};
    for (std::size_t j = 0; j < k.landmarks.size(); ++j) {
      if (k.landmarks[j] >= landmarks.size())
        return Error{at + ": landmark index " + std::to_string(k.landmarks[j]) + " of " +
                     std::to_string(landmarks.size())};
      if (j > 0 && k.landmarks[j] <= k.landmarks[j - 1])
        return Error{at + ": landmark indices not ascending"};
    }
  }
  keys.clear();
  for (std::size_t i = 0; i < landmarks.size(); ++i) {
    // Positions travel as floats: beyond 1000 km they are not a map.
    if (!finite(landmarks[i].p_O) || landmarks[i].p_O.cwiseAbs().maxCoeff() > 1e6)
      return Error{"map_down: landmark " + std::to_string(i) + ": position not finite or beyond 1e6 m"};
    if (!keys.insert(landmarks[i].origin).second)
      return Error{"map_down: landmark " + std::to_string(i) + ": origin key sent twice"};
  }
  return Status::Ok();
}

Expected<std::vector<std::uint8_t>> encodeMapDown(const MapDownPacket& p) {
  if (Status s = p.validate(); !s) return Error{s.error()};
  Writer w;
  w.bytes(kPacketMagic, 4);
  w.le(kMapDownVersion, 1);
  w.bytes(p.agent.data(), p.agent.size());
  w.le(p.epoch, 8);
  w.le(p.session, 4);
  w.le(p.seq, 8);
  w.pose(p.T_W_O);
  w.varint(p.keyframes.size());
  for (const BorrowedKeyframe& k : p.keyframes) {
    w.key(k.origin);
    w.f64(k.stamp);
    w.pose(k.T_O_C);
    w.varint(k.landmarks.size());
    std::uint32_t prev = 0;
    for (std::uint32_t l : k.landmarks) {
      w.varint(l - prev);
      prev = l;
    }
  }
  w.varint(p.landmarks.size());
  for (const BorrowedLandmark& l : p.landmarks) {
    w.key(l.origin);
    for (int i = 0; i < 3; ++i) w.f32(static_cast<float>(l.p_O[i]));
    w.bytes(l.descriptor.data(), l.descriptor.size());
  }
  sealCrc(&w.out);
  return std::move(w.out);
}

Expected<MapDownPacket> decodeMapDown(const std::uint8_t* data, std::size_t size,
                                      const std::string& origin) {
  if (Status s = checkFrame(data, size, kPacketMagic, 4 + 1 + 16 + 8 + 4 + 8 + 56 + 2 + 4, origin); !s)
    return Error{s.error()};
  try {
    Reader r(data + 4, size - 8, origin);
    const auto version = static_cast<std::uint8_t>(r.le(1, "version"));
    if (version != kMapDownVersion)
      return Error{origin + ": map_down version " + std::to_string(version) + ", this build reads " +
                   std::to_string(kMapDownVersion)};
    MapDownPacket p;
    r.bytes(p.agent.data(), p.agent.size(), "agent");
    p.epoch = r.le(8, "epoch");
    p.session = static_cast<std::uint32_t>(r.le(4, "session"));
    p.seq = r.le(8, "seq");
    p.T_W_O = r.pose("T_W_O");
    p.keyframes.resize(r.count(kMinKeyframeBytes, "keyframe"));
    for (BorrowedKeyframe& k : p.keyframes) {
      k.origin = r.key("keyframe origin");
      k.stamp = r.f64("keyframe stamp");
      k.T_O_C = r.pose("keyframe pose");
      k.landmarks.resize(r.count(1, "keyframe landmark"));
      std::uint64_t prev = 0;
      for (std::uint32_t& l : k.landmarks) {
        prev += r.varint("keyframe landmark index");
        if (prev > 0xFFFFFFFFu) throw wire::DecodeError(origin + ": landmark index out of range");
        l = static_cast<std::uint32_t>(prev);
      }
    }
    p.landmarks.resize(r.count(kMinLandmarkBytes, "landmark"));
    for (BorrowedLandmark& l : p.landmarks) {
      l.origin = r.key("landmark origin");
      for (int i = 0; i < 3; ++i) l.p_O[i] = r.f32("landmark position");
      r.bytes(l.descriptor.data(), l.descriptor.size(), "landmark descriptor");
    }
    if (r.left() != 0)
      return Error{origin + ": " + std::to_string(r.left()) + " bytes after the landmarks"};
    if (Status s = p.validate(); !s) return Error{origin + ": " + s.error()};
    return p;
  } catch (const wire::DecodeError& e) {
    return Error{e.what()};
  }
}

std::vector<std::uint8_t> encodeMapDownAck(const MapDownAck& ack) {
  Writer w;
  w.bytes(kAckMagic, 4);
  w.bytes(ack.agent.data(), ack.agent.size());
  w.le(ack.epoch, 8);
  w.le(ack.seq, 8);
  sealCrc(&w.out);
  return std::move(w.out);
}

Expected<MapDownAck> decodeMapDownAck(const std::uint8_t* data, std::size_t size,
                                      const std::string& origin) {
  if (Status s = checkFrame(data, size, kAckMagic, kAckBytes, origin); !s) return Error{s.error()};
  if (size != kAckBytes)
    return Error{origin + ": " + std::to_string(size) + " bytes, an ack has " +
                 std::to_string(kAckBytes)};
  MapDownAck ack;
  std::memcpy(ack.agent.data(), data + 4, 16);
  ack.epoch = getLE(data + 20, 8);
  ack.seq = getLE(data + 28, 8);
  if (ack.seq == 0) return Error{origin + ": ack of seq 0"};
  return ack;
}

}  // namespace hermes
