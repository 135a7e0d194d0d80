// Wire format: CRC-32, round trips, exact byte accounting, and rejection of
// truncated, corrupted, oversized and crafted frames (without big allocations).
#include <gtest/gtest.h>
#include <zstd.h>

#include <atomic>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <new>
#include <random>

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

void expectSame(const Submap& a, const Submap& b) {
  EXPECT_EQ(a.header.agent, b.header.agent);
  EXPECT_EQ(a.header.session, b.header.session);
  EXPECT_EQ(a.header.seq, b.header.seq);
  EXPECT_EQ(a.header.t_start, b.header.t_start);
  EXPECT_EQ(a.header.t_end, b.header.t_end);
  ASSERT_EQ(a.cameras.size(), b.cameras.size());
  for (std::size_t c = 0; c < a.cameras.size(); ++c) {
    EXPECT_EQ(a.cameras[c].fx, b.cameras[c].fx);
    EXPECT_EQ(a.cameras[c].fy, b.cameras[c].fy);
    EXPECT_EQ(a.cameras[c].cx, b.cameras[c].cx);
    EXPECT_EQ(a.cameras[c].cy, b.cameras[c].cy);
    EXPECT_EQ(a.cameras[c].width, b.cameras[c].width);
    EXPECT_EQ(a.cameras[c].height, b.cameras[c].height);
  }
  ASSERT_EQ(a.keyframes.size(), b.keyframes.size());
  for (std::size_t i = 0; i < a.keyframes.size(); ++i) {
    const Keyframe& x = a.keyframes[i];
    const Keyframe& y = b.keyframes[i];
    EXPECT_EQ(x.id, y.id);
    EXPECT_EQ(x.stamp, y.stamp);
    EXPECT_EQ(x.camera_id, y.camera_id);
    EXPECT_LT((x.T_A_C.matrix() - y.T_A_C.matrix()).cwiseAbs().maxCoeff(), 1e-12);
    ASSERT_EQ(x.keypoints.size(), y.keypoints.size());
    for (std::size_t k = 0; k < x.keypoints.size(); ++k) {
      EXPECT_EQ(x.keypoints[k].u, y.keypoints[k].u);
      EXPECT_EQ(x.keypoints[k].v, y.keypoints[k].v);
      EXPECT_EQ(x.keypoints[k].octave, y.keypoints[k].octave);
      EXPECT_EQ(x.keypoints[k].depth, y.keypoints[k].depth);
    }
    EXPECT_EQ(x.descriptors, y.descriptors);
    EXPECT_EQ(x.keypoint_landmark, y.keypoint_landmark);
  }
  ASSERT_EQ(a.landmarks.size(), b.landmarks.size());
  for (std::size_t j = 0; j < a.landmarks.size(); ++j) {
    const Landmark& x = a.landmarks[j];
    const Landmark& y = b.landmarks[j];
    EXPECT_EQ(x.id, y.id);
    // Positions travel as floats: exactly the float rounding of the original.
    EXPECT_EQ(x.p_A.cast<float>().cast<double>(), y.p_A);
    EXPECT_LE((x.p_A - y.p_A).norm(), 1e-6 * x.p_A.norm());
    EXPECT_EQ(x.descriptor, y.descriptor);
    ASSERT_EQ(x.observations.size(), y.observations.size());
    for (std::size_t o = 0; o < x.observations.size(); ++o) {
      EXPECT_EQ(x.observations[o].keyframe, y.observations[o].keyframe);
      EXPECT_EQ(x.observations[o].keypoint, y.observations[o].keypoint);
    }
  }
  ASSERT_EQ(a.odometry.size(), b.odometry.size());
  for (std::size_t i = 0; i < a.odometry.size(); ++i) {
    EXPECT_EQ(a.odometry[i].from, b.odometry[i].from);
    EXPECT_EQ(a.odometry[i].to, b.odometry[i].to);
    EXPECT_LT((a.odometry[i].T_from_to.matrix() - b.odometry[i].T_from_to.matrix())
                  .cwiseAbs().maxCoeff(), 1e-12);
    // Information travels as 21 floats of the upper triangle.
    const Mat6 expected = a.odometry[i].information.cast<float>().cast<double>();
    for (int r = 0; r < 6; ++r)
      for (int c = 0; c < 6; ++c)
        EXPECT_EQ(b.odometry[i].information(r, c), expected(std::min(r, c), std::max(r, c)));
  }
}

std::string decodeError(const std::vector<std::uint8_t>& f, const DecodeLimits& l = {}) {
  auto d = decodeSubmap(f, l);
  return d.ok() ? std::string("<decoded>") : d.error();
}

}  // namespace

TEST(Crc32, KnownVectorsAndIncremental) {
  EXPECT_EQ(crc32("123456789", 9), 0xCBF43926u);
  EXPECT_EQ(crc32("", 0), 0u);
  EXPECT_EQ(crc32("The quick brown fox jumps over the lazy dog", 43), 0x414FA339u);
  std::mt19937 rng(5);
  std::vector<std::uint8_t> data(1000);
  for (auto& b : data) b = static_cast<std::uint8_t>(rng());
  for (std::size_t n : {0u, 1u, 7u, 8u, 9u, 63u, 1000u}) {
    std::uint32_t ref = 0xFFFFFFFFu;  // bitwise reference
    for (std::size_t i = 0; i < n; ++i) {
      ref ^= data[i];
      for (int k = 0; k < 8; ++k) ref = (ref & 1) ? (ref >> 1) ^ 0xEDB88320u : ref >> 1;
    }
    EXPECT_EQ(crc32(data.data(), n), ~ref) << n;
    for (std::size_t split = 0; split <= n; split += 13)
      EXPECT_EQ(crc32(data.data() + split, n - split, crc32(data.data(), split)), ~ref);
  }
}

TEST(WireFormat, RoundTripRandomSubmaps) {
  for (std::uint64_t seed = 1; seed <= 6; ++seed) {
    SyntheticSubmapOptions o;
    o.keyframes = 1 + static_cast<int>(seed % 5);
    o.keypoints_per_keyframe = 40 + 30 * static_cast<int>(seed);
    o.landmarks = 60 * static_cast<int>(seed);
    o.cameras = 1 + static_cast<int>(seed % 2);
    o.random_ids = seed % 2 == 0;
    o.seed = seed;
    const Submap s = makeSyntheticSubmap(o);
    ASSERT_EQ(s.validate(), "");
    ASSERT_GT(s.observationCount(), 0u);
    for (bool zstd : {false, true}) {
      WireOptions wo;
      wo.zstd = zstd;
      const auto frame = encodeOk(s, wo);
      auto decoded = decodeSubmap(frame);
      ASSERT_TRUE(decoded.ok()) << decoded.error();
      SCOPED_TRACE("seed " + std::to_string(seed) + (zstd ? " zstd" : " raw"));
      expectSame(s, *decoded);
      auto peek = peekFrame(frame.data(), frame.size());
      ASSERT_TRUE(peek.ok()) << peek.error();
      EXPECT_EQ(peek->compressed(), zstd);
      EXPECT_EQ(peek->routing.seq, s.header.seq);
      EXPECT_EQ(peek->routing.agent, s.header.agent);
      EXPECT_EQ(peek->routing.session, s.header.session);
      EXPECT_EQ(peek->raw_bytes + kWireFixedBytes, encodedSizeUncompressed(s));
    }
  }
}

TEST(WireFormat, EmptySubmap) {
  Submap s;
  s.header.seq = 9;
  const auto frame = encodeOk(s);
  EXPECT_EQ(frame.size(), kWireFixedBytes + 5);  // marker + four zero counts
  EXPECT_EQ(encodedSizeUncompressed(s), frame.size());
  auto d = decodeSubmap(frame);
  ASSERT_TRUE(d.ok()) << d.error();
  expectSame(s, *d);
  WireOptions z;
  z.zstd = true;
  auto dz = decodeSubmap(encodeOk(s, z));
  ASSERT_TRUE(dz.ok()) << dz.error();
  expectSame(s, *dz);
}

TEST(WireFormat, ExactByteAccounting) {
  SyntheticSubmapOptions o;
  o.keyframes = 10;
  o.keypoints_per_keyframe = 800;
  o.landmarks = 3000;
  const Submap s = makeSyntheticSubmap(o);
  WireStats st;
  const auto frame = encodeOk(s, {}, &st);
  EXPECT_EQ(st.total, frame.size());
  EXPECT_EQ(st.frame, frame.size());
  EXPECT_EQ(encodedSizeUncompressed(s), frame.size());
  EXPECT_EQ(st.header + st.keyframes + st.keypoints + st.descriptors + st.landmarks +
                st.observations + st.odometry, st.total);
  EXPECT_EQ(st.keypoints, 13u * 8000);
  EXPECT_EQ(st.descriptors, 32u * 8000);
  EXPECT_EQ(st.odometry, 9u * (2 + 56 + 84));
  EXPECT_EQ(st.header, kWireFixedBytes + 1 + 1 + 40 + 1 + 2 + 1);
  // Observations: 1-byte keyframe index + 2-byte keypoint index (>= 128) or 1.
  EXPECT_GE(st.observations, 2 * s.observationCount());
  EXPECT_LE(st.observations, 3 * s.observationCount());
  // Landmarks: id delta (1 byte, ids nearly consecutive) + 12 + 32 + count.
  // First id (>= 50000) as a 3-byte delta from 0.
  EXPECT_EQ(st.landmarks, 46u * 3000 + 2);

  WireStats zs;
  WireOptions z;
  z.zstd = true;
  const auto packed = encodeOk(s, z, &zs);
  EXPECT_EQ(zs.total, st.total);
  EXPECT_EQ(zs.frame, packed.size());
  EXPECT_LT(packed.size(), frame.size());

  // The byte model is linear: one more observation costs its two index varints
  // (keyframe index < 128: 1 byte; keypoint index: 1 or 2 bytes), one more
  // landmark without observations 46 bytes.
  Submap s2 = makeSyntheticSubmap(o);
  Keyframe& kf = s2.keyframes[3];
  std::uint32_t free_kp = 0;
  while (kf.keypoint_landmark.at(free_kp) != kInvalidId) ++free_kp;
  const std::size_t obs_cost = 1 + (free_kp < 128 ? 1 : 2);
  s2.landmarks[5].observations.push_back({kf.id, free_kp});
  kf.keypoint_landmark[free_kp] = s2.landmarks[5].id;
  EXPECT_EQ(encodedSizeUncompressed(s2), frame.size() + obs_cost);
  Landmark extra;
  extra.id = s2.landmarks.back().id + 1;
  s2.landmarks.push_back(extra);
  EXPECT_EQ(encodedSizeUncompressed(s2), frame.size() + obs_cost + 46);
  EXPECT_EQ(encodeOk(s2).size(), frame.size() + obs_cost + 46);
}

TEST(WireFormat, HandBuiltFrameFollowsTheDocumentedLayout) {
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
  EXPECT_EQ(d->keyframes[0].keypoints[1].u, 11.f);
  EXPECT_EQ(d->keyframes[0].keypoint_landmark, (std::vector<LandmarkId>{kInvalidId, 7}));
  EXPECT_EQ(d->landmarks[0].p_A, Vec3(1, 2, 3));
  EXPECT_EQ(d->header.seq, 77u);
  EXPECT_EQ(d->header.session, 5u);
  EXPECT_EQ(d->cameras[0].width, 640);
}

TEST(WireFormat, RejectsEveryTruncation) {
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

TEST(WireFormat, RejectsEveryBitFlip) {
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

TEST(WireFormat, RejectsBadMagicVersionFlagsAndOversize) {
  const auto frame = encodeOk(smallSubmap());
  auto f = frame;
  f[0] = 'X';
  EXPECT_EQ(decodeError(f), "wire: bad magic");
  f = frame;
  setLE(&f, 4, 7, 2);
  reseal(&f);
  EXPECT_EQ(decodeError(f), "wire: version 7 not supported (this build reads 1)");
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

TEST(WireFormat, RejectsZstdBombAndLyingLengths) {
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

TEST(WireFormat, AbsurdCountsWithValidCrcAllocateNothingBig) {
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

TEST(WireFormat, RejectsInconsistentBodies) {
  auto decodeBody = [](const Bytes& w) {
    return decodeError(frameAround(w.b, 0, static_cast<std::uint32_t>(w.b.size())));
  };
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
    w.b[w.b.size() - 2] = 3;  // camera id 3
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

TEST(WireFormat, EncoderRefusesWhatTheDecoderWouldReject) {
  Submap s = smallSubmap();
  s.landmarks[0].observations.push_back({999, 0});
  auto e = encodeSubmap(s);
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.error().find("unknown keyframe 999"), std::string::npos) << e.error();

  s = smallSubmap();
  ASSERT_FALSE(s.landmarks[1].observations.empty());
  s.landmarks[0].observations.push_back(s.landmarks[1].observations[0]);
  e = encodeSubmap(s);
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.error().find("is observed by landmarks"), std::string::npos) << e.error();

  s = smallSubmap();
  s.landmarks[0].p_A.x() = 1e300;
  EXPECT_FALSE(encodeSubmap(s).ok());
  s = smallSubmap();
  s.keyframes[0].keypoints[0].depth = std::numeric_limits<float>::infinity();
  EXPECT_FALSE(encodeSubmap(s).ok());
}

TEST(WireFormat, KeypointLinksAreRebuiltFromObservations) {
  Submap s = smallSubmap();
  // A link to a landmark that is not in the submap (e.g. dropped by distillation).
  Keyframe& kf = s.keyframes[0];
  std::size_t k = 0;
  while (kf.keypoint_landmark[k] != kInvalidId) ++k;
  kf.keypoint_landmark[k] = 123456789;
  auto d = decodeSubmap(encodeOk(s));
  ASSERT_TRUE(d.ok()) << d.error();
  EXPECT_EQ(d->keyframes[0].keypoint_landmark[k], kInvalidId);
  kf.keypoint_landmark[k] = kInvalidId;
  EXPECT_EQ(d->keyframes[0].keypoint_landmark, kf.keypoint_landmark);
}

TEST(WireFormat, StreamOfFramesSplitsByParsedHeader) {
  std::vector<std::uint8_t> stream;
  for (std::uint64_t seed : {11u, 12u, 13u}) {
    WireOptions o;
    o.zstd = seed == 12;
    const auto f = encodeOk(smallSubmap(seed), o);
    stream.insert(stream.end(), f.begin(), f.end());
  }
  std::size_t at = 0;
  int frames = 0;
  while (at < stream.size()) {
    // Only the fixed header is needed to learn the frame length.
    auto h = parseFrameHeader(stream.data() + at, kWireFixedBytes);
    ASSERT_TRUE(h.ok()) << h.error();
    ASSERT_LE(at + h->frameBytes(), stream.size());
    auto d = decodeSubmap(stream.data() + at, h->frameBytes());
    ASSERT_TRUE(d.ok()) << d.error();
    EXPECT_EQ(d->header.seq, smallSubmap(11 + frames).header.seq);
    at += h->frameBytes();
    ++frames;
  }
  EXPECT_EQ(frames, 3);
  EXPECT_FALSE(peekFrame(stream.data(), stream.size()).ok());  // peek wants one whole frame
  EXPECT_NE(parseFrameHeader(stream.data(), 10).error().find("truncated"), std::string::npos);
}
