// Wire format: CRC-32, round trips, exact byte accounting, stream splitting.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

#include "hermes/core/crc32.h"
#include "hermes/core/wire_format.h"
#include "hermes/core/wire_synthetic.h"

using namespace hermes;

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
    EXPECT_EQ(x.lost_before, y.lost_before);
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
    Submap s = makeSyntheticSubmap(o);
    if (seed % 3 == 0) s.keyframes.back().lost_before = true;  // a relocalisation
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
