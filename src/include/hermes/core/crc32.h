// CRC-32 as in IEEE 802.3 / zlib / PNG (reflected polynomial 0xEDB88320, initial
// value and final xor 0xFFFFFFFF). crc32("123456789") == 0xCBF43926.
#pragma once

#include <cstddef>
#include <cstdint>

namespace hermes {

/// CRC-32 of `size` bytes. Incremental like zlib: pass the previous result as
/// `crc` to continue a checksum over several pieces (start with 0).
std::uint32_t crc32(const void* data, std::size_t size, std::uint32_t crc = 0);

}  // namespace hermes
