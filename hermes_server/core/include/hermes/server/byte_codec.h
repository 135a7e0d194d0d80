// Little helpers for the server's own binary files (global map, checkpoint):
// a writer that appends plain values, and a bounds-checked reader that never
// trusts a count. Values are written in host byte order (little-endian on every
// platform Hermes runs on); the files carry a magic, a version and a CRC-32.
//
// The reader fails (returns false) instead of reading past its end, and
// count() refuses a count whose elements, at their minimum encoded size, could
// not fit in the bytes that remain: a damaged or crafted file cannot make a
// decoder allocate more than a small multiple of its size.
#pragma once

#include <cstdint>
#include <cstring>
#include <string>
#include <type_traits>
#include <vector>

#include "hermes/core/geometry.h"
#include "hermes/core/map_types.h"
#include "hermes/core/metrics.h"

namespace hermes {
namespace server {

class ByteWriter {
 public:
  template <class T>
  void pod(const T& v) {
    static_assert(std::is_trivially_copyable<T>::value, "pod() needs a trivially copyable type");
    const auto* p = reinterpret_cast<const std::uint8_t*>(&v);
    out.insert(out.end(), p, p + sizeof(T));
  }
  void flag(bool b) { pod(static_cast<std::uint8_t>(b ? 1 : 0)); }
  void count(std::size_t n) { pod(static_cast<std::uint64_t>(n)); }
  void pose(const SE3& T);
  void key(const KeyframeKey& k);
  void mat6(const Mat6& m);
  void vec3(const Vec3& v);
  void text(const std::string& s);
  void blob(const std::uint8_t* data, std::size_t size);
  void blob(const std::vector<std::uint8_t>& b) { blob(b.data(), b.size()); }

  std::vector<std::uint8_t> out;
};

class ByteReader {
 public:
  ByteReader(const std::uint8_t* data, std::size_t size) : data_(data), end_(size) {}

  template <class T>
  bool pod(T* v) {
    static_assert(std::is_trivially_copyable<T>::value, "pod() needs a trivially copyable type");
    if (sizeof(T) > end_ - pos_) return false;
    std::memcpy(v, data_ + pos_, sizeof(T));
    pos_ += sizeof(T);
    return true;
  }
  /// A byte that must be 0 or 1.
  bool flag(bool* b);
  /// A count of elements of at least `min_element_bytes` each (>= 1) that must
  /// fit in what remains.
  bool count(std::uint64_t* n, std::size_t min_element_bytes);
  /// Finite translation, finite non-degenerate quaternion (normalised).
  bool pose(SE3* T);
  bool key(KeyframeKey* k) { return pod(&k->agent) && pod(&k->session) && pod(&k->id); }
  bool mat6(Mat6* m);  ///< finite entries
  bool vec3(Vec3* v);  ///< finite entries
  bool text(std::string* s);
  bool blob(std::vector<std::uint8_t>* b);

  std::size_t pos() const { return pos_; }
  std::size_t remaining() const { return end_ - pos_; }
  bool atEnd() const { return pos_ == end_; }

 private:
  const std::uint8_t* data_;
  std::size_t pos_ = 0;
  std::size_t end_;
};

/// Every sample of every stage.
void saveTimings(ByteWriter* w, const TimingStats& t);
/// Into `t` (added to what it holds); false on damaged input.
bool loadTimings(ByteReader* r, TimingStats* t);

}  // namespace server
}  // namespace hermes
