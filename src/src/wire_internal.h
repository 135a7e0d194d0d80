// Private helpers of the wire format: memory stream buffers for cereal, LEB128
// varints, little-endian fixed fields, and the minimum encoded sizes the decoder
// checks counts against. Not installed; only wire_*.cc include it.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <streambuf>
#include <string>
#include <vector>

#include "hermes/core/map_types.h"

namespace hermes {
namespace wire {

static_assert(sizeof(Descriptor) == 32, "Descriptor must be 32 packed bytes");

// Minimum encoded size of one element of each counted container (varints count 1).
constexpr std::size_t kCameraBytes = 4 * 8 + 2 * 4;
constexpr std::size_t kPoseBytes = 7 * 8;
constexpr std::size_t kMinKeyframeBytes = 1 + 8 + kPoseBytes + 1 + 1 + 1;
constexpr std::uint8_t kKeyframeFlagLostBefore = 1;
constexpr std::size_t kKeypointBytes = 4 + 4 + 1 + 4;
constexpr std::size_t kDescriptorBytes = 32;
constexpr std::size_t kMinLandmarkBytes = 1 + 3 * 4 + kDescriptorBytes + 1;
constexpr std::size_t kMinObservationBytes = 2;
constexpr std::size_t kInformationBytes = 21 * 4;
constexpr std::size_t kMinOdometryBytes = 1 + 1 + kPoseBytes + kInformationBytes;
constexpr std::uint8_t kLittleEndianMarker = 1;

/// Thrown inside the decoder, turned into an Error at the API boundary.
struct DecodeError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// Appends everything written to a std::vector (output of cereal archives).
class VectorOutBuf : public std::streambuf {
 public:
  explicit VectorOutBuf(std::vector<std::uint8_t>* out) : out_(out) {}

 protected:
  std::streamsize xsputn(const char* s, std::streamsize n) override {
    out_->insert(out_->end(), reinterpret_cast<const std::uint8_t*>(s),
                 reinterpret_cast<const std::uint8_t*>(s) + n);
    return n;
  }
  int_type overflow(int_type ch) override {
    if (traits_type::eq_int_type(ch, traits_type::eof())) return traits_type::not_eof(ch);
    out_->push_back(static_cast<std::uint8_t>(ch));
    return ch;
  }

 private:
  std::vector<std::uint8_t>* out_;
};

/// Read-only stream buffer over caller-owned bytes; never reads past the end.
class MemoryInBuf : public std::streambuf {
 public:
  MemoryInBuf(const std::uint8_t* data, std::size_t size) {
    char* p = const_cast<char*>(reinterpret_cast<const char*>(data));
    setg(p, p, p + size);
  }
  std::size_t remaining() const { return static_cast<std::size_t>(egptr() - gptr()); }
  std::size_t offset() const { return static_cast<std::size_t>(gptr() - eback()); }
};

inline std::size_t varintSize(std::uint64_t v) {
  std::size_t n = 1;
  while (v >= 0x80) {
    v >>= 7;
    ++n;
  }
  return n;
}

/// LEB128 bytes of v into buf (at least 10 bytes); returns the length.
inline std::size_t putVarint(std::uint64_t v, std::uint8_t* buf) {
  std::size_t n = 0;
  while (v >= 0x80) {
    buf[n++] = static_cast<std::uint8_t>(v | 0x80);
    v >>= 7;
  }
  buf[n++] = static_cast<std::uint8_t>(v);
  return n;
}

/// Zigzag of the wrapping difference id - prev: small for nearby ids either way.
inline std::uint64_t zigzagDelta(std::uint64_t id, std::uint64_t prev) {
  const std::uint64_t d = id - prev;
  return (d << 1) ^ (0 - (d >> 63));
}
inline std::uint64_t unzigzagDelta(std::uint64_t z, std::uint64_t prev) {
  const std::uint64_t d = (z >> 1) ^ (0 - (z & 1));
  return prev + d;
}

inline void putLE(std::uint8_t* p, std::uint64_t v, int bytes) {
  for (int i = 0; i < bytes; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}
inline std::uint64_t getLE(const std::uint8_t* p, int bytes) {
  std::uint64_t v = 0;
  for (int i = 0; i < bytes; ++i) v |= std::uint64_t{p[i]} << (8 * i);
  return v;
}
inline std::uint64_t doubleBits(double d) {
  std::uint64_t u;
  std::memcpy(&u, &d, 8);
  return u;
}
inline double bitsDouble(std::uint64_t u) {
  double d;
  std::memcpy(&d, &u, 8);
  return d;
}

/// CRC of a whole frame: bytes [0, kWireCrcOffset) then [kWireCrcOffset + 4, size).
std::uint32_t frameCrc(const std::uint8_t* frame, std::size_t size);

/// Fills the fixed 64 bytes of `frame` (whose body already follows them):
/// magic, version, flags, lengths, routing header, and finally the CRC.
void sealFrame(std::vector<std::uint8_t>* frame, const SubmapHeader& routing,
               std::uint16_t flags, std::uint32_t raw_bytes);

/// Appends the body (cereal portable binary, uncompressed) of a submap that has
/// passed the encoder's checks (valid, finite, no keypoint observed twice).
void writeBody(const Submap& s, std::vector<std::uint8_t>* out);

/// Decodes a body; throws DecodeError naming what failed and the body offset.
/// The routing header is not part of the body and is left default.
Submap readBody(const std::uint8_t* data, std::size_t size);

}  // namespace wire
}  // namespace hermes
