// The downlink packet format (map_down.h): round trips, refusals naming what
// failed, and a bounded mutation fuzz (every mutant a clean error or a packet
// that passes validate() and round-trips).
#include <gtest/gtest.h>

#include <chrono>
#include <random>

#include "hermes/core/crc32.h"
#include "hermes/core/map_down.h"

using namespace hermes;

namespace {

MapDownPacket packet(std::uint64_t seed, int keyframes = 3, int landmarks = 40) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-20, 20);
  MapDownPacket p;
  p.agent = uuidFromSeed(seed);
  p.epoch = 3;
  p.session = 2;
  p.seq = 7;
  p.T_W_O = SE3::exp((Vec6() << 1, -2, 0.5, 0.1, 0.2, -0.3).finished());
  for (int i = 0; i < landmarks; ++i) {
    BorrowedLandmark l;
    l.origin = {1, 1, 1000u + static_cast<std::uint64_t>(i)};
    l.p_O = Vec3(u(rng), u(rng), u(rng));
    for (auto& b : l.descriptor) b = static_cast<std::uint8_t>(rng());
    p.landmarks.push_back(l);
  }
  for (int k = 0; k < keyframes; ++k) {
    BorrowedKeyframe kf;
    kf.origin = {1, 1, static_cast<std::uint64_t>(10 + k)};
    kf.stamp = 3.5 + k;
    kf.T_O_C = SE3::exp((Vec6() << u(rng), u(rng), 1, 0.3 * k, 0, 0.1).finished());
    for (int i = k; i < landmarks; i += 2) kf.landmarks.push_back(static_cast<std::uint32_t>(i));
    p.keyframes.push_back(kf);
  }
  return p;
}

void expectSame(const MapDownPacket& a, const MapDownPacket& b) {
  EXPECT_EQ(a.agent, b.agent);
  EXPECT_EQ(a.epoch, b.epoch);
  EXPECT_EQ(a.session, b.session);
  EXPECT_EQ(a.seq, b.seq);
  EXPECT_LT((a.T_W_O.matrix() - b.T_W_O.matrix()).norm(), 1e-12);
  ASSERT_EQ(a.keyframes.size(), b.keyframes.size());
  for (std::size_t i = 0; i < a.keyframes.size(); ++i) {
    EXPECT_EQ(a.keyframes[i].origin, b.keyframes[i].origin);
    EXPECT_EQ(a.keyframes[i].stamp, b.keyframes[i].stamp);
    EXPECT_LT((a.keyframes[i].T_O_C.matrix() - b.keyframes[i].T_O_C.matrix()).norm(), 1e-12);
    EXPECT_EQ(a.keyframes[i].landmarks, b.keyframes[i].landmarks);
  }
  ASSERT_EQ(a.landmarks.size(), b.landmarks.size());
  for (std::size_t i = 0; i < a.landmarks.size(); ++i) {
    EXPECT_EQ(a.landmarks[i].origin, b.landmarks[i].origin);
    EXPECT_LT((a.landmarks[i].p_O - b.landmarks[i].p_O).norm(), 1e-5);  // floats on the wire
    EXPECT_EQ(a.landmarks[i].descriptor, b.landmarks[i].descriptor);
  }
}

void reseal(std::vector<std::uint8_t>* f) {
  const std::uint32_t c = crc32(f->data(), f->size() - 4);
  for (int i = 0; i < 4; ++i) (*f)[f->size() - 4 + i] = static_cast<std::uint8_t>(c >> (8 * i));
}

}  // namespace

TEST(MapDown, RoundTripsPacketsAndAcks) {
  for (const MapDownPacket& p : {packet(1), packet(2, 0, 0), packet(3, 1, 300)}) {
    auto bytes = encodeMapDown(p);
    ASSERT_TRUE(bytes.ok()) << bytes.error();
    auto back = decodeMapDown(bytes->data(), bytes->size());
    ASSERT_TRUE(back.ok()) << back.error();
    expectSame(p, *back);
  }
  // About a descriptor, a position and a short key per landmark: the budget's unit.
  auto big = encodeMapDown(packet(4, 1, 1000));
  ASSERT_TRUE(big.ok());
  EXPECT_LT(big->size(), 1000u * 56u);
  const MapDownAck ack{uuidFromSeed(9), 5, 42};
  const auto ab = encodeMapDownAck(ack);
  auto back = decodeMapDownAck(ab.data(), ab.size());
  ASSERT_TRUE(back.ok()) << back.error();
  EXPECT_EQ(back->agent, ack.agent);
  EXPECT_EQ(back->epoch, 5u);
  EXPECT_EQ(back->seq, 42u);
}

TEST(MapDown, RefusesInvalidPacketsNamingTheProblem) {
  MapDownPacket p = packet(5);
  p.seq = 0;
  EXPECT_NE(encodeMapDown(p).error().find("seq 0"), std::string::npos);
  p = packet(5);
  p.keyframes[1].landmarks.push_back(999);
  EXPECT_NE(encodeMapDown(p).error().find("keyframe 1: landmark index 999"), std::string::npos);
  p = packet(5);
  p.landmarks[3].origin = p.landmarks[2].origin;
  EXPECT_NE(encodeMapDown(p).error().find("landmark 3: origin key sent twice"), std::string::npos);
  p = packet(5);
  p.landmarks[0].p_O.x() = 1e9;
  EXPECT_FALSE(encodeMapDown(p).ok());
}

TEST(MapDown, RefusesCorruptedTruncatedAndForeignFrames) {
  const auto good = *encodeMapDown(packet(6));
  auto flipped = good;
  flipped[50] ^= 0x10;
  EXPECT_NE(decodeMapDown(flipped.data(), flipped.size()).error().find("CRC mismatch"),
            std::string::npos);
  auto cut = std::vector<std::uint8_t>(good.begin(), good.begin() + 100);
  reseal(&cut);
  EXPECT_NE(decodeMapDown(cut.data(), cut.size(), "/r1/map_down").error().find("/r1/map_down"),
            std::string::npos);
  auto other = good;
  other[4] = 9;  // version
  reseal(&other);
  EXPECT_NE(decodeMapDown(other.data(), other.size()).error().find("version 9, this build reads 1"),
            std::string::npos);
  auto ack = encodeMapDownAck({uuidFromSeed(1), 1, 3});
  EXPECT_NE(decodeMapDown(ack.data(), ack.size()).error().find("magic"), std::string::npos);
  EXPECT_FALSE(decodeMapDown(nullptr, 0).ok());
  ack[25] ^= 1;
  EXPECT_FALSE(decodeMapDownAck(ack.data(), ack.size()).ok());
}

TEST(MapDown, FuzzedFramesDecodeCleanlyOrRoundTrip) {
  std::mt19937_64 rng(20261202);
  std::vector<std::vector<std::uint8_t>> seeds;
  for (int s = 0; s < 4; ++s) seeds.push_back(*encodeMapDown(packet(10 + s, s, 10 * s)));
  const auto t0 = std::chrono::steady_clock::now();
  int decoded = 0, refused = 0;
  for (int it = 0; it < 60000; ++it) {
    if (std::chrono::steady_clock::now() - t0 > std::chrono::seconds(4)) break;
    std::vector<std::uint8_t> f = seeds[rng() % seeds.size()];
    const int edits = 1 + static_cast<int>(rng() % 4);
    for (int e = 0; e < edits && !f.empty(); ++e) {
      const std::size_t at = rng() % f.size();
      switch (rng() % 4) {
        case 0: f[at] ^= static_cast<std::uint8_t>(1u << (rng() % 8)); break;
        case 1: f[at] = static_cast<std::uint8_t>(rng()); break;
        case 2: f.resize(at); break;
        default: f.insert(f.begin() + static_cast<std::ptrdiff_t>(at), static_cast<std::uint8_t>(rng()));
      }
    }
    if (f.size() >= 4 && rng() % 4 != 0) reseal(&f);  // reach the body decoder
    auto p = decodeMapDown(f.data(), f.size(), "fuzz");
    if (!p.ok()) {
      EXPECT_EQ(p.error().rfind("fuzz", 0), 0u) << p.error();
      ++refused;
      continue;
    }
    ++decoded;
    ASSERT_TRUE(p->validate().ok());
    auto again = encodeMapDown(*p);
    ASSERT_TRUE(again.ok()) << again.error();
    auto back = decodeMapDown(again->data(), again->size());
    ASSERT_TRUE(back.ok()) << back.error();
    expectSame(*p, *back);
  }
  EXPECT_GT(refused, 1000);
  EXPECT_GT(decoded, 0);
}
