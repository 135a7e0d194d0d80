// The Hermes submap wire format (DESIGN.md §4): a framed, versioned, CRC-protected
// binary encoding of a Submap. Every uplink byte figure in Hermes is counted on
// these bytes, so the encoding is compact and its size is exactly predictable.
//
// Frame layout (all integers little-endian):
//
//   offset size  field
//   ------ ----  -------------------------------------------------------------
//        0    4  magic "HRMS"
//        4    2  format version (this build writes and reads kWireVersion)
//        6    2  flags: bit 0 = body is zstd-compressed; bit 1 = a 32-byte
//                authentication tag follows the body (frame_auth.h); other
//                bits must be 0 (decoders before the tag existed reject a
//                tagged frame with "unknown flags 0x00000002")
//        8    4  body length in bytes, as stored (after compression)
//       12    4  raw body length (before compression; == body length if not)
//       16    4  CRC-32 (IEEE 802.3) over bytes [0,16) then [20, end of frame),
//                the tag included
//       20   44  routing header, never compressed, so a receiver can route,
//                deduplicate and acknowledge without decoding (peekFrame):
//                  agent uuid (16 bytes), session u32, seq u64,
//                  t_start f64, t_end f64
//       64    n  body: the submap, written with cereal's PortableBinaryOutputArchive
//                (little-endian) and optionally zstd-compressed as one zstd frame
//   64+n   32  (flag bit 1 only) HMAC-SHA256 tag with the robot's key over bytes
//                [0,16) then [20, 64+n): every header field but the CRC, and the
//                body (frame_auth.h). The decoder skips it; receivers verify it.
//
// Body (v2; v1 had no keyframe flags byte). "vu" is an unsigned LEB128 varint (canonical: no redundant trailing
// 0x80 groups), "vz" a zigzag varint of the difference to the previous id:
//
//   u8 endianness marker (cereal; must be 1 = little-endian)
//   vu n_cameras;   n_cameras × { f64 fx, fy, cx, cy; u32 width, height }
//   vu n_keyframes; n_keyframes × {
//       vz id; f64 stamp; f64 qw, qx, qy, qz, tx, ty, tz (T_A_C); vu camera_id;
//       u8 flags (v2; bit 0 = Keyframe::lost_before, other bits must be 0);
//       vu n_keypoints; f32 u[n]; f32 v[n]; u8 octave[n]; f32 depth[n];
//       u8 descriptors[32 n] }
//   vu n_landmarks; n_landmarks × {
//       vz id; f32 x, y, z (p_A); u8 descriptor[32];
//       vu n_obs; n_obs × { vu keyframe index (into this submap); vu keypoint } }
//   vu n_odometry;  n_odometry × {
//       vu from index; vu to index; f64 qw, qx, qy, qz, tx, ty, tz (T_from_to);
//       f32 information upper triangle, row-major (21 values) }
//
// Choices that set the byte model:
// * Landmark positions are floats: a float keeps 24 significant bits, i.e. 6 µm
//   at 100 m and 60 µm at 1 km from the agent origin, far below the mm–cm
//   uncertainty of a triangulated point, and saves 12 bytes per landmark.
//   Keyframe and odometry poses stay double (the server's pose graph chains
//   them), and they are few.
// * Observations live only on landmarks (keyframe *index* + keypoint index, ≈3
//   bytes); Keyframe::keypoint_landmark is rebuilt from them on decode. So a
//   keypoint_landmark entry whose landmark is not in the submap, or does not list
//   that observation, is not transmitted (it decodes as kInvalidId).
// * Keypoint columns are stored per field (all u, all v, ...), which compresses
//   better and lets cereal move each column in one call.
// * No bag-of-words vector is sent: the server computes it from the descriptors
//   with its own vocabulary, so vocabulary changes never touch the wire.
//
// Decoding never trusts a count: before anything is reserved, count × (minimum
// encoded size of one element) must fit in the bytes that remain, so a crafted
// frame cannot make the decoder allocate more than a small multiple of its size
// (plus DecodeLimits::max_raw_bytes for a compressed body). After decoding,
// Submap::validate() must pass. Errors start with "wire: " and name what failed
// and where (body offsets are in the uncompressed body).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "hermes/core/map_types.h"
#include "hermes/core/status.h"

namespace hermes {

constexpr std::uint16_t kWireVersion = 2;
constexpr std::size_t kWireFrameHeaderBytes = 20;    ///< magic .. CRC
constexpr std::size_t kWireRoutingHeaderBytes = 44;  ///< uuid, session, seq, t_start, t_end
constexpr std::size_t kWireFixedBytes = kWireFrameHeaderBytes + kWireRoutingHeaderBytes;
constexpr std::size_t kWireCrcOffset = 16;
constexpr std::uint16_t kWireFlagZstd = 1u << 0;
constexpr std::uint16_t kWireFlagTag = 1u << 1;   ///< an authentication tag trails the body
constexpr std::size_t kWireTagBytes = 32;         ///< HMAC-SHA256

struct WireOptions {
  bool zstd = false;   ///< compress the body with zstd
  int zstd_level = 3;  ///< zstd compression level (1..19 sensible)
};

struct DecodeLimits {
  std::size_t max_frame_bytes = std::size_t{64} << 20;  ///< whole frame as received
  std::size_t max_raw_bytes = std::size_t{256} << 20;   ///< body after decompression
};

/// What peekFrame() learns from the fixed 64 bytes (after checking the CRC).
struct FrameHeader {
  std::uint16_t version = 0;
  std::uint16_t flags = 0;
  std::uint32_t body_bytes = 0;  ///< body as stored
  std::uint32_t raw_bytes = 0;   ///< body uncompressed
  std::uint32_t crc = 0;
  SubmapHeader routing;          ///< agent, session, seq, t_start, t_end
  bool compressed() const { return (flags & kWireFlagZstd) != 0; }
  bool tagged() const { return (flags & kWireFlagTag) != 0; }
  std::size_t tagBytes() const { return tagged() ? kWireTagBytes : 0; }
  std::size_t frameBytes() const { return kWireFixedBytes + body_bytes + tagBytes(); }
};

/// Exact byte accounting of an encoding, before compression. The parts add up to
/// `total`; `frame` is what is really sent (equal to `total` without zstd).
struct WireStats {
  std::size_t total = 0;
  std::size_t header = 0;        ///< frame + routing header, marker, cameras, section counts
  std::size_t keyframes = 0;     ///< per keyframe: id, stamp, pose, camera, keypoint count
  std::size_t keypoints = 0;     ///< 13 bytes per keypoint
  std::size_t descriptors = 0;   ///< 32 bytes per keypoint
  std::size_t landmarks = 0;     ///< per landmark: id, position, descriptor, observation count
  std::size_t observations = 0;  ///< per observation: keyframe index, keypoint index
  std::size_t odometry = 0;      ///< per edge: indices, pose, information
  std::size_t frame = 0;         ///< bytes of the frame as sent (after compression)
};

/// Encodes a submap into one frame. Fails (without aborting) when the submap is
/// not valid (Submap::validate()), holds non-finite values, has two landmarks
/// observing the same keypoint, or would exceed the 4 GiB a frame can describe.
/// `stats` (optional) receives the exact byte accounting.
Expected<std::vector<std::uint8_t>> encodeSubmap(const Submap& submap,
                                                 const WireOptions& options = {},
                                                 WireStats* stats = nullptr);

/// Exact byte accounting of encodeSubmap() without encoding (frame == total).
/// Assumes a submap that encodeSubmap() would accept.
WireStats wireStats(const Submap& submap);

/// Exact size of the uncompressed frame; equals encodeSubmap(s).size() without zstd.
std::size_t encodedSizeUncompressed(const Submap& submap);

/// Parses the fixed 64 bytes at the start of `data` (which may hold more than one
/// frame, or only the start of one): checks magic, version, flags and the limits,
/// but NOT the CRC, so the routing info is unverified. For stream readers that
/// must learn frameBytes() before the whole frame has arrived.
Expected<FrameHeader> parseFrameHeader(const std::uint8_t* data, std::size_t size,
                                       const DecodeLimits& limits = {});

/// Checks the fixed header, the frame length and the CRC, and returns the header
/// with its routing info, without decoding or decompressing the body.
Expected<FrameHeader> peekFrame(const std::uint8_t* data, std::size_t size,
                                const DecodeLimits& limits = {});

/// Decodes one frame of exactly `size` bytes. Never crashes, never allocates
/// more than the limits and the frame size justify; the result passes validate().
Expected<Submap> decodeSubmap(const std::uint8_t* data, std::size_t size,
                              const DecodeLimits& limits = {});

inline Expected<Submap> decodeSubmap(const std::vector<std::uint8_t>& frame,
                                     const DecodeLimits& limits = {}) {
  return decodeSubmap(frame.data(), frame.size(), limits);
}

}  // namespace hermes
