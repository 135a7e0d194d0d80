// Authenticated frames (DESIGN.md §9, server durability and trust): every robot
// holds a pre-shared 32-byte key; a frame carries an HMAC-SHA256 tag (OpenSSL)
// over its header and body, so the server can tell a robot's frames from forged
// ones before it decodes anything.
//
// Tag layout (wire_format.h): flag bit 1 (kWireFlagTag) set, 32 tag bytes after
// the body, tag = HMAC-SHA256(key, bytes [0,16) ‖ bytes [20, 64 + body)), i.e.
// every header field except the CRC (magic, version, flags with the tag bit set,
// lengths, the routing header with uuid, session and seq) and the body as
// stored. The CRC is computed last and covers the tag too: it keeps catching
// transmission errors, the tag catches everything else.
//
// Key files: one per robot, named `<robot>.key`, holding the key as 64
// hexadecimal digits (one line). They must not be readable by group or others
// (mode 0600, as `./hermes keys add` writes them); readKeyFile refuses others.
// A robot's uuid is agentUuid(<robot>) (map_types.h), so a key directory names
// the robots a server accepts (keyring.h).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "hermes/core/status.h"

namespace hermes {

constexpr std::size_t kFrameKeyBytes = 32;

struct FrameKey {
  std::array<std::uint8_t, kFrameKeyBytes> bytes{};
};

/// Reads a key file (64 hex digits, optional trailing newline). Errors name the
/// file and the problem: missing, readable by group/others, not 64 hex digits.
Expected<FrameKey> readKeyFile(const std::string& path);
/// Parses 64 hex digits (what a key file holds); `where` names the source in errors.
Expected<FrameKey> parseKeyHex(const std::string& text, const std::string& where);

/// Returns a copy of a well-formed frame (peekFrame passes) carrying the tag for
/// `key`: flag bit 1 set, tag appended, CRC recomputed. A frame that is already
/// tagged gets its tag replaced (e.g. spooled under an earlier key).
Expected<std::vector<std::uint8_t>> signFrame(const std::uint8_t* data, std::size_t size,
                                              const FrameKey& key);
inline Expected<std::vector<std::uint8_t>> signFrame(const std::vector<std::uint8_t>& frame,
                                                     const FrameKey& key) {
  return signFrame(frame.data(), frame.size(), key);
}

enum class TagCheck {
  kValid,     ///< the tag is the key's HMAC of this frame
  kMissing,   ///< the frame carries no tag (flag bit 1 clear)
  kMismatch,  ///< a tag, but not this key's for these bytes
  kMalformed  ///< not a well-formed frame (peekFrame fails)
};
const char* toString(TagCheck check);

/// Checks a frame's tag against `key` (constant-time comparison, CRYPTO_memcmp).
TagCheck verifyFrameTag(const std::uint8_t* data, std::size_t size, const FrameKey& key);

}  // namespace hermes
