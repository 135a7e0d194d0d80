// Wire format: rejection of truncated, corrupted, oversized and crafted frames,
// without big allocations (checked by counting the largest operator new).
#include <gtest/gtest.h>
#include <zstd.h>

#include <atomic>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <new>

#include "hermes/core/crc32.h"
#include "hermes/core/wire_format.h"
#include "hermes/core/wire_synthetic.h"

using namespace hermes;

// ---- allocation tracking: the largest single allocation while tracking is on ----
namespace {
std::atomic<bool> g_track{false};
std::atomic<std::size_t> g_largest{0};
void* trackedAlloc(std::size_t n) {
  if (g_track.load(std::memory_order_relaxed)) {
    std::size_t prev = g_largest.load();
    while (n > prev && !g_largest.compare_exchange_weak(prev, n)) {
    }
  }
  void* p = std::malloc(n ? n : 1);
  if (!p) throw std::bad_alloc();
  return p;
}
struct AllocationProbe {
  AllocationProbe() { g_largest = 0; g_track = true; }
  ~AllocationProbe() { g_track = false; }
  std::size_t largest() const { return g_largest.load(); }
};
}  // namespace
void* operator new(std::size_t n) { return trackedAlloc(n); }
void* operator new[](std::size_t n) { return trackedAlloc(n); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }

namespace {

std::vector<std::uint8_t> encodeOk(const Submap& s, const WireOptions& o = {},
                                   WireStats* stats = nullptr) {
  auto frame = encodeSubmap(s, o, stats);
  EXPECT_TRUE(frame.ok()) << frame.error();
  return frame.ok() ? frame.value() : std::vector<std::uint8_t>{};
}

Submap smallSubmap(std::uint64_t seed = 3) {
  SyntheticSubmapOptions o;
  o.keyframes = 2;
  o.keypoints_per_keyframe = 6;
  o.landmarks = 4;
  o.seed = seed;
  return makeSyntheticSubmap(o);
}

// Hand-built frames following the layout documented in wire_format.h.
struct Bytes {
  std::vector<std::uint8_t> b;
  void le(std::uint64_t v, int n) {
    for (int i = 0; i < n; ++i) b.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
  }
  void f64(double d) { std::uint64_t u; std::memcpy(&u, &d, 8); le(u, 8); }
  void f32(float f) { std::uint32_t u; std::memcpy(&u, &f, 4); le(u, 4); }
  void vu(std::uint64_t v) {
    while (v >= 0x80) { b.push_back(static_cast<std::uint8_t>(v | 0x80)); v >>= 7; }
    b.push_back(static_cast<std::uint8_t>(v));
  }
  void fill(std::uint8_t v, int n) { b.insert(b.end(), n, v); }
  void identityPose() { f64(1); f64(0); f64(0); f64(0); f64(0); f64(0); f64(0); }
};

void reseal(std::vector<std::uint8_t>* f) {
  std::uint8_t* p = f->data();
  std::uint32_t c = crc32(p, kWireCrcOffset);
  c = crc32(p + kWireCrcOffset + 4, f->size() - kWireCrcOffset - 4, c);
  for (int i = 0; i < 4; ++i) p[kWireCrcOffset + i] = static_cast<std::uint8_t>(c >> (8 * i));
}

void setLE(std::vector<std::uint8_t>* f, std::size_t at, std::uint64_t v, int n) {
  for (int i = 0; i < n; ++i) (*f)[at + i] = static_cast<std::uint8_t>(v >> (8 * i));
}

std::vector<std::uint8_t> frameAround(const std::vector<std::uint8_t>& body, std::uint16_t flags,
                                      std::uint32_t raw) {
  Bytes h;
  h.b = {'H', 'R', 'M', 'S'};
  h.le(kWireVersion, 2);
  h.le(flags, 2);
  h.le(body.size(), 4);
  h.le(raw, 4);
  h.le(0, 4);        // CRC, filled by reseal
  h.fill(0xab, 16);  // agent uuid
  h.le(5, 4);        // session
  h.le(77, 8);       // seq
  h.f64(1.0);
  h.f64(2.0);
  h.b.insert(h.b.end(), body.begin(), body.end());
  reseal(&h.b);
  return h.b;
}

// One camera, one keyframe with `kps` keypoints, landmarks appended by caller.
Bytes bodyWithOneKeyframe(int kps) {
  Bytes w;
  w.b.push_back(1);  // cereal little-endian marker
  w.vu(1);
  for (double v : {400.0, 400.0, 320.0, 240.0}) w.f64(v);
  w.le(640, 4);
  w.le(480, 4);
  w.vu(1);   // keyframes
  w.vu(20);  // zigzag(+10): id 10
  w.f64(3.5);
  w.identityPose();
  w.vu(0);  // camera 0
  w.b.push_back(1);  // flags: lost before
  w.vu(kps);
  for (int k = 0; k < kps; ++k) w.f32(10.f + k);  // u
  for (int k = 0; k < kps; ++k) w.f32(20.f);      // v
  for (int k = 0; k < kps; ++k) w.b.push_back(0); // octave
  for (int k = 0; k < kps; ++k) w.f32(2.f);       // depth
  w.fill(0x5a, 32 * kps);
  return w;
}

void appendLandmark(Bytes* w, std::uint64_t zigzag_id, std::uint64_t n_obs) {
  w->vu(zigzag_id);
  w->f32(1.f); w->f32(2.f); w->f32(3.f);
  w->fill(0x11, 32);
  w->vu(n_obs);
}

std::string decodeError(const std::vector<std::uint8_t>& f, const DecodeLimits& l = {}) {
  auto d = decodeSubmap(f, l);
  return d.ok() ? std::string("<decoded>") : d.error();
}

}  // namespace

TEST(WireReject, HandBuiltFrameFollowsTheDocumentedLayout) {
  Bytes w = bodyWithOneKeyframe(2);
  w.vu(1);
  appendLandmark(&w, 2 * 7, 1);  // landmark id 7 seen by keyframe #0 keypoint 1
  w.vu(0);
  w.vu(1);
  w.vu(0);  // no odometry
  auto d = decodeSubmap(frameAround(w.b, 0, static_cast<std::uint32_t>(w.b.size())));
  ASSERT_TRUE(d.ok()) << d.error();
  ASSERT_EQ(d->keyframes.size(), 1u);
  EXPECT_EQ(d->keyframes[0].id, 10u);
  EXPECT_EQ(d->keyframes[0].stamp, 3.5);
  EXPECT_TRUE(d->keyframes[0].lost_before);
  EXPECT_EQ(d->keyframes[0].keypoints[1].u, 11.f);
  EXPECT_EQ(d->keyframes[0].keypoint_landmark, (std::vector<LandmarkId>{kInvalidId, 7}));
  EXPECT_EQ(d->landmarks[0].p_A, Vec3(1, 2, 3));
  EXPECT_EQ(d->header.seq, 77u);
  EXPECT_EQ(d->header.session, 5u);
  EXPECT_EQ(d->cameras[0].width, 640);
}

TEST(WireReject, RejectsEveryTruncation) {
  const auto frame = encodeOk(smallSubmap());
  ASSERT_LT(frame.size(), 2000u);
  for (std::size_t n = 0; n < frame.size(); ++n) {
    auto d = decodeSubmap(frame.data(), n);
    ASSERT_FALSE(d.ok()) << "prefix " << n;
    EXPECT_NE(d.error().find("wire: frame truncated"), std::string::npos) << d.error();
  }
  EXPECT_NE(decodeError(std::vector<std::uint8_t>(frame.begin(), frame.end() - 3))
                .find("header says " + std::to_string(frame.size()) + " bytes, have " +
                      std::to_string(frame.size() - 3)),
            std::string::npos);
  auto longer = frame;
  longer.push_back(0);
  EXPECT_NE(decodeError(longer).find("1 trailing bytes"), std::string::npos);
}

TEST(WireReject, RejectsEveryBitFlip) {
  for (bool zstd : {false, true}) {
    WireOptions o;
    o.zstd = zstd;
    const auto frame = encodeOk(smallSubmap(), o);
    for (std::size_t bit = 0; bit < 8 * frame.size(); ++bit) {
      auto f = frame;
      f[bit / 8] ^= static_cast<std::uint8_t>(1u << (bit % 8));
      ASSERT_FALSE(decodeSubmap(f).ok()) << "bit " << bit;
      if (bit / 8 >= kWireFixedBytes) {
        EXPECT_NE(decodeError(f).find("wire: CRC mismatch"), std::string::npos);
      }
    }
  }
}

TEST(WireReject, RejectsBadMagicVersionFlagsAndOversize) {
  const auto frame = encodeOk(smallSubmap());
  auto f = frame;
  f[0] = 'X';
  EXPECT_EQ(decodeError(f), "wire: bad magic");
  f = frame;
  setLE(&f, 4, 7, 2);
  reseal(&f);
  EXPECT_EQ(decodeError(f), "wire: version 7 not supported (this build reads 2)");
  f = frame;
  setLE(&f, 4, 1, 2);  // v1 had no keyframe flags: refused, not misread
  reseal(&f);
  EXPECT_EQ(decodeError(f), "wire: version 1 not supported (this build reads 2)");
  f = frame;
  setLE(&f, 6, 0x8000, 2);
  reseal(&f);
  EXPECT_NE(decodeError(f).find("unknown flags 0x00008000"), std::string::npos);
  f = frame;
  f[20] ^= 1;  // routing header is covered by the CRC
  EXPECT_NE(decodeError(f).find("CRC mismatch (header says 0x"), std::string::npos);

  // A header claiming a huge body is rejected before the bytes are even needed.
  f = std::vector<std::uint8_t>(frame.begin(), frame.begin() + kWireFixedBytes);
  setLE(&f, 8, 0xFFFFFFF0u, 4);
  setLE(&f, 12, 0xFFFFFFF0u, 4);
  EXPECT_NE(decodeError(f).find("exceeds the limit of 67108864"), std::string::npos)
      << decodeError(f);
  DecodeLimits tight;
  tight.max_frame_bytes = frame.size() - 1;
  EXPECT_NE(decodeError(frame, tight).find("exceeds the limit"), std::string::npos);
  tight.max_frame_bytes = frame.size();
  EXPECT_TRUE(decodeSubmap(frame, tight).ok());
}

TEST(WireReject, RejectsZstdBombAndLyingLengths) {
  // 8 MiB of zeros compress to a few hundred bytes.
  std::vector<std::uint8_t> zeros(8 << 20, 0);
  std::vector<std::uint8_t> packed(ZSTD_compressBound(zeros.size()));
  packed.resize(ZSTD_compress(packed.data(), packed.size(), zeros.data(), zeros.size(), 3));
  ASSERT_LT(packed.size(), 2000u);
  DecodeLimits limits;
  limits.max_raw_bytes = 1 << 20;
  auto bomb = frameAround(packed, kWireFlagZstd, static_cast<std::uint32_t>(zeros.size()));
  {
    AllocationProbe probe;
    EXPECT_NE(decodeError(bomb, limits).find("(uncompressed) exceeds the limit of 1048576"),
              std::string::npos);
    EXPECT_LT(probe.largest(), 64u << 10);
  }
  // The header lies low about the raw size: zstd's own content size disagrees.
  auto liar = frameAround(packed, kWireFlagZstd, 1000);
  EXPECT_NE(decodeError(liar).find("zstd frame declares 8388608 bytes but the header says 1000"),
            std::string::npos);
  // Within the limit the zeros decompress, and the body is then rejected cleanly.
  limits.max_raw_bytes = 16 << 20;
  EXPECT_NE(decodeError(bomb, limits).find("endianness marker is 0"), std::string::npos);
  // Uncompressed frames must not claim a different raw size.
  auto f = encodeOk(smallSubmap());
  setLE(&f, 12, 5, 4);
  reseal(&f);
  EXPECT_NE(decodeError(f).find("raw length 5"), std::string::npos);
}

TEST(WireReject, AbsurdCountsWithValidCrcAllocateNothingBig) {
  struct Case {
    std::vector<std::uint8_t> body;
    std::string expect;
  };
  std::vector<Case> cases;
  {
    Bytes w;
    w.b.push_back(1);
    w.vu(0);
    w.vu(std::uint64_t{1} << 62);
    cases.push_back({w.b, "keyframe count 4611686018427387904 exceeds remaining 0 bytes"});
  }
  {
    Bytes w;
    w.b.push_back(1);
    w.vu(0xFFFFFFFFu);
    w.fill(0, 100);
    cases.push_back({w.b, "camera count 4294967295 exceeds remaining 100 bytes"});
  }
  {
    Bytes w = bodyWithOneKeyframe(1);
    w.vu(1);
    appendLandmark(&w, 2, 4000000000u);
    w.fill(0, 37);
    cases.push_back({w.b, "landmark #0 observation count 4000000000 exceeds remaining 37 bytes"});
  }
  {
    Bytes w = bodyWithOneKeyframe(0);
    w.b.pop_back();  // replace the keypoint count 0 by a huge one
    w.vu(3000000000u);
    w.fill(0, 500);
    cases.push_back({w.b, "keyframe #0 keypoint count 3000000000 exceeds remaining 500 bytes"});
  }
  {
    Bytes w = bodyWithOneKeyframe(1);
    w.vu(0);
    w.vu(1u << 30);
    cases.push_back({w.b, "odometry edge count 1073741824 exceeds remaining 0 bytes"});
  }
  {
    Bytes w;
    w.b.push_back(1);
    w.fill(0xff, 12);  // an endless varint
    cases.push_back({w.b, "camera count varint overflows 64 bits"});
  }
  for (const Case& c : cases) {
    const auto frame = frameAround(c.body, 0, static_cast<std::uint32_t>(c.body.size()));
    AllocationProbe probe;
    const std::string err = decodeError(frame);
    EXPECT_NE(err.find("wire: " + c.expect), std::string::npos) << err;
    EXPECT_NE(err.find("(body offset "), std::string::npos) << err;
    EXPECT_LT(probe.largest(), 16u << 10) << err;
  }
}

TEST(WireReject, RejectsInconsistentBodies) {
  auto decodeBody = [](const Bytes& w) {
    return decodeError(frameAround(w.b, 0, static_cast<std::uint32_t>(w.b.size())));
  };
  {  // a keyframe flag this version does not define
    Bytes w = bodyWithOneKeyframe(2);
    w.b[1 + 1 + 40 + 1 + 1 + 8 + 56 + 1] = 0x03;  // marker, cameras, keyframe count, id, stamp, pose, camera
    w.vu(0);
    w.vu(0);
    EXPECT_NE(decodeBody(w).find("keyframe #0 has unknown flags 3"), std::string::npos) << decodeBody(w);
  }
  {  // two landmarks claim the same keypoint
    Bytes w = bodyWithOneKeyframe(2);
    w.vu(2);
    appendLandmark(&w, 2, 1);
    w.vu(0); w.vu(1);
    appendLandmark(&w, 2, 1);
    w.vu(0); w.vu(1);
    w.vu(0);
    EXPECT_NE(decodeBody(w).find("keypoint 1 is already observed by landmark 1"),
              std::string::npos) << decodeBody(w);
  }
  {  // observation of a keypoint that does not exist
    Bytes w = bodyWithOneKeyframe(2);
    w.vu(1);
    appendLandmark(&w, 2, 1);
    w.vu(0); w.vu(2);
    w.vu(0);
    EXPECT_NE(decodeBody(w).find("keypoint 2 is out of range (keyframe 10 has 2)"),
              std::string::npos) << decodeBody(w);
  }
  {  // keyframe index out of range
    Bytes w = bodyWithOneKeyframe(2);
    w.vu(1);
    appendLandmark(&w, 2, 1);
    w.vu(1); w.vu(0);
    w.vu(0);
    EXPECT_NE(decodeBody(w).find("keyframe index 1 is out of range (1 available)"),
              std::string::npos) << decodeBody(w);
  }
  {  // unknown camera is caught by Submap::validate()
    Bytes w = bodyWithOneKeyframe(0);
    w.b[w.b.size() - 3] = 3;  // camera id 3 (before the flags byte and the keypoint count)
    w.vu(0); w.vu(0);
    EXPECT_NE(decodeBody(w).find("not valid: keyframe 10 uses camera 3"), std::string::npos)
        << decodeBody(w);
  }
  {  // non-canonical varint, trailing body bytes, bad endianness marker
    Bytes w = bodyWithOneKeyframe(0);
    w.vu(0); w.vu(0);
    Bytes nc = w;
    nc.b.back() = 0x80;
    nc.b.push_back(0x00);
    EXPECT_NE(decodeBody(nc).find("not in canonical form"), std::string::npos);
    Bytes tail = w;
    tail.b.push_back(9);
    EXPECT_NE(decodeBody(tail).find("1 unread bytes at the end of the body"), std::string::npos);
    Bytes be = w;
    be.b[0] = 0;
    EXPECT_NE(decodeBody(be).find("endianness marker is 0"), std::string::npos);
  }
  {  // NaN in a pose
    Bytes w = bodyWithOneKeyframe(0);
    const std::size_t pose_at = 1 + 1 + 40 + 1 + 1 + 8;
    const double nan = std::numeric_limits<double>::quiet_NaN();
    std::memcpy(&w.b[pose_at + 8 * 4], &nan, 8);
    w.vu(0); w.vu(0);
    EXPECT_NE(decodeBody(w).find("keyframe #0 pose is not finite"), std::string::npos)
        << decodeBody(w);
  }
}
