// Little-endian integers in the MQTT payloads (mqtt_messages.h, mqtt_global_pose.h).
#pragma once

#include <cstdint>
#include <vector>

namespace hermes::transport::le {

/// Appends the low `n` bytes of v, least significant first.
inline void put(std::vector<std::uint8_t>* out, std::uint64_t v, int n) {
  for (int i = 0; i < n; ++i) out->push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}

/// Reads `n` bytes at p, least significant first.
inline std::uint64_t get(const std::uint8_t* p, int n) {
  std::uint64_t v = 0;
  for (int i = 0; i < n; ++i) v |= std::uint64_t{p[i]} << (8 * i);
  return v;
}

}  // namespace hermes::transport::le
