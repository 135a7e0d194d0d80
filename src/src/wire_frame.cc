// Frame level of the wire format: the fixed header and routing header, the CRC,
// limits, zstd decompression, and the decodeSubmap() entry point.
#include <zstd.h>

#include <cmath>
#include <cstdio>
#include <memory>

#include "hermes/core/crc32.h"
#include "hermes/core/wire_format.h"
#include "wire_internal.h"

namespace hermes {
namespace wire {
namespace {

constexpr std::uint8_t kMagic[4] = {'H', 'R', 'M', 'S'};

std::string hex32(std::uint32_t v) {
  char buf[16];
  std::snprintf(buf, sizeof(buf), "0x%08x", v);
  return buf;
}

struct DCtxDeleter {
  void operator()(ZSTD_DCtx* c) const { ZSTD_freeDCtx(c); }
};

/// Decompresses a zstd body into exactly `raw_bytes` bytes (already checked
/// against the limit). The zstd frame must be single, declare its content size,
/// and agree with the header, so nothing is allocated for a false claim.
Expected<std::unique_ptr<std::uint8_t[]>> decompressBody(const std::uint8_t* body,
                                                         std::size_t body_bytes,
                                                         std::uint32_t raw_bytes) {
  const unsigned long long declared = ZSTD_getFrameContentSize(body, body_bytes);
  if (declared == ZSTD_CONTENTSIZE_ERROR)
    return Error{"wire: compressed body is not a zstd frame"};
  if (declared == ZSTD_CONTENTSIZE_UNKNOWN)
    return Error{"wire: zstd frame does not declare its content size"};
  if (declared != raw_bytes)
    return Error{"wire: zstd frame declares " + std::to_string(declared) +
                 " bytes but the header says " + std::to_string(raw_bytes)};
  const std::size_t frame_len = ZSTD_findFrameCompressedSize(body, body_bytes);
  if (ZSTD_isError(frame_len))
    return Error{std::string("wire: zstd frame is malformed: ") + ZSTD_getErrorName(frame_len)};
  if (frame_len != body_bytes)
    return Error{"wire: " + std::to_string(body_bytes - frame_len) +
                 " bytes follow the zstd frame in the body"};
  static thread_local std::unique_ptr<ZSTD_DCtx, DCtxDeleter> dctx(ZSTD_createDCtx());
  if (!dctx) return Error{"wire: cannot create a zstd decompression context"};
  std::unique_ptr<std::uint8_t[]> raw(new std::uint8_t[raw_bytes > 0 ? raw_bytes : 1]);
  const std::size_t n = ZSTD_decompressDCtx(dctx.get(), raw.get(), raw_bytes, body, body_bytes);
  if (ZSTD_isError(n)) {
    ZSTD_DCtx_reset(dctx.get(), ZSTD_reset_session_only);
    return Error{std::string("wire: zstd decompression failed: ") + ZSTD_getErrorName(n)};
  }
  if (n != raw_bytes)
    return Error{"wire: zstd body decompressed to " + std::to_string(n) + " bytes, header says " +
                 std::to_string(raw_bytes)};
  return raw;
}

}  // namespace

std::uint32_t frameCrc(const std::uint8_t* frame, std::size_t size) {
  const std::uint32_t c = crc32(frame, kWireCrcOffset);
  return crc32(frame + kWireCrcOffset + 4, size - kWireCrcOffset - 4, c);
}

void sealFrame(std::vector<std::uint8_t>* frame, const SubmapHeader& routing,
               std::uint16_t flags, std::uint32_t raw_bytes) {
  std::uint8_t* p = frame->data();
  std::copy(kMagic, kMagic + 4, p);
  putLE(p + 4, kWireVersion, 2);
  putLE(p + 6, flags, 2);
  putLE(p + 8, frame->size() - kWireFixedBytes, 4);
  putLE(p + 12, raw_bytes, 4);
  std::uint8_t* r = p + kWireFrameHeaderBytes;
  std::copy(routing.agent.begin(), routing.agent.end(), r);
  putLE(r + 16, routing.session, 4);
  putLE(r + 20, routing.seq, 8);
  putLE(r + 28, doubleBits(routing.t_start), 8);
  putLE(r + 36, doubleBits(routing.t_end), 8);
  putLE(p + kWireCrcOffset, frameCrc(p, frame->size()), 4);
}

}  // namespace wire

Expected<FrameHeader> parseFrameHeader(const std::uint8_t* data, std::size_t size,
                                       const DecodeLimits& limits) {
  using namespace wire;
  if (size >= 4 && !std::equal(kMagic, kMagic + 4, data)) return Error{"wire: bad magic"};
  if (size < kWireFixedBytes)
    return Error{"wire: frame truncated: have " + std::to_string(size) +
                 " bytes, the fixed header needs " + std::to_string(kWireFixedBytes)};
  FrameHeader h;
  h.version = static_cast<std::uint16_t>(getLE(data + 4, 2));
  h.flags = static_cast<std::uint16_t>(getLE(data + 6, 2));
  h.body_bytes = static_cast<std::uint32_t>(getLE(data + 8, 4));
  h.raw_bytes = static_cast<std::uint32_t>(getLE(data + 12, 4));
  h.crc = static_cast<std::uint32_t>(getLE(data + kWireCrcOffset, 4));
  if (h.version != kWireVersion)
    return Error{"wire: version " + std::to_string(h.version) + " not supported (this build reads " +
                 std::to_string(kWireVersion) + ")"};
  if (h.flags & ~(kWireFlagZstd | kWireFlagTag)) return Error{"wire: unknown flags " + hex32(h.flags)};
  if (h.frameBytes() > limits.max_frame_bytes)
    return Error{"wire: frame of " + std::to_string(h.frameBytes()) +
                 " bytes exceeds the limit of " + std::to_string(limits.max_frame_bytes)};
  if (h.raw_bytes > limits.max_raw_bytes)
    return Error{"wire: body of " + std::to_string(h.raw_bytes) +
                 " bytes (uncompressed) exceeds the limit of " +
                 std::to_string(limits.max_raw_bytes)};
  if (!h.compressed() && h.raw_bytes != h.body_bytes)
    return Error{"wire: uncompressed frame with body length " + std::to_string(h.body_bytes) +
                 " but raw length " + std::to_string(h.raw_bytes)};
  const std::uint8_t* r = data + kWireFrameHeaderBytes;
  std::copy(r, r + 16, h.routing.agent.begin());
  h.routing.session = static_cast<std::uint32_t>(getLE(r + 16, 4));
  h.routing.seq = getLE(r + 20, 8);
  h.routing.t_start = bitsDouble(getLE(r + 28, 8));
  h.routing.t_end = bitsDouble(getLE(r + 36, 8));
  return h;
}

Expected<FrameHeader> peekFrame(const std::uint8_t* data, std::size_t size,
                                const DecodeLimits& limits) {
  using namespace wire;
  Expected<FrameHeader> parsed = parseFrameHeader(data, size, limits);
  if (!parsed) return parsed;
  const FrameHeader& h = *parsed;
  if (size < h.frameBytes())
    return Error{"wire: frame truncated: header says " + std::to_string(h.frameBytes()) +
                 " bytes, have " + std::to_string(size)};
  if (size > h.frameBytes())
    return Error{"wire: " + std::to_string(size - h.frameBytes()) +
                 " trailing bytes after a frame of " + std::to_string(h.frameBytes()) + " bytes"};
  const std::uint32_t crc = frameCrc(data, size);
  if (crc != h.crc)
    return Error{"wire: CRC mismatch (header says " + hex32(h.crc) + ", computed " + hex32(crc) +
                 ")"};
  if (!std::isfinite(h.routing.t_start) || !std::isfinite(h.routing.t_end))
    return Error{"wire: routing header window stamps are not finite"};
  return parsed;
}

Expected<Submap> decodeSubmap(const std::uint8_t* data, std::size_t size,
                              const DecodeLimits& limits) {
  using namespace wire;
  Expected<FrameHeader> header = peekFrame(data, size, limits);
  if (!header) return Error{header.error()};
  const std::uint8_t* body = data + kWireFixedBytes;
  std::unique_ptr<std::uint8_t[]> raw;
  if (header->compressed()) {
    auto unpacked = decompressBody(body, header->body_bytes, header->raw_bytes);
    if (!unpacked) return Error{unpacked.error()};
    raw = std::move(unpacked.value());
    body = raw.get();
  }
  Submap submap;
  try {
    submap = readBody(body, header->raw_bytes);
  } catch (const DecodeError& e) {
    return Error{e.what()};
  } catch (const std::exception& e) {  // e.g. cereal::Exception; not expected
    return Error{std::string("wire: body could not be read: ") + e.what()};
  }
  submap.header = header->routing;
  const std::string problem = submap.validate();
  if (!problem.empty()) return Error{"wire: decoded submap is not valid: " + problem};
  return submap;
}

}  // namespace hermes
