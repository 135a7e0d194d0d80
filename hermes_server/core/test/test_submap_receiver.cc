#include <gtest/gtest.h>

#include <chrono>
#include <random>

#include "hermes/core/wire_synthetic.h"
#include "hermes/server/submap_receiver.h"

using namespace hermes;

namespace {
std::vector<std::uint8_t> frameFor(std::uint64_t agent_seed, std::uint32_t session, std::uint64_t seq) {
  SyntheticSubmapOptions o;
  o.keyframes = 3;
  o.keypoints_per_keyframe = 60;
  o.landmarks = 80;
  o.seed = agent_seed * 1000 + seq;
  Submap s = makeSyntheticSubmap(o);
  s.header.agent = uuidFromSeed(agent_seed);
  s.header.session = session;
  s.header.seq = seq;
  auto f = encodeSubmap(s, WireOptions{});
  EXPECT_TRUE(f.ok()) << f.error();
  return *f;
}
}  // namespace

TEST(SubmapReceiver, AcceptsOnceAcksDuplicatesRejectsGarbage) {
  Bookkeeper books;
  std::vector<ReceivedSubmap> applied;
  SubmapReceiver rx(&books, [&](ReceivedSubmap&& s) { applied.push_back(std::move(s)); });
  const auto f0 = frameFor(1, 0, 0), f1 = frameFor(1, 0, 1);
  auto r = rx.receive(f0.data(), f0.size(), nullptr, 1.0);
  EXPECT_EQ(r.verdict, ArrivalVerdict::kAccept);
  EXPECT_TRUE(r.acknowledge);
  r = rx.receive(f0.data(), f0.size(), nullptr, 2.0);  // resend
  EXPECT_EQ(r.verdict, ArrivalVerdict::kDuplicate);
  EXPECT_TRUE(r.acknowledge);
  r = rx.receive(f1.data(), f1.size(), nullptr, 3.0);
  EXPECT_EQ(r.verdict, ArrivalVerdict::kAccept);
  ASSERT_EQ(applied.size(), 2u);
  EXPECT_EQ(applied[1].submap.header.seq, 1u);

  auto bad = f1;
  bad[bad.size() / 2] ^= 0x10;
  r = rx.receive(bad.data(), bad.size(), nullptr, 4.0);
  EXPECT_EQ(r.verdict, ArrivalVerdict::kRejected);
  EXPECT_FALSE(r.acknowledge);
  EXPECT_NE(r.reason.find("CRC"), std::string::npos) << r.reason;

  SubmapHeader lie;
  lie.agent = uuidFromSeed(1);
  lie.session = 0;
  lie.seq = 7;
  const auto f2 = frameFor(1, 0, 2);
  r = rx.receive(f2.data(), f2.size(), &lie, 5.0);
  EXPECT_EQ(r.verdict, ArrivalVerdict::kRejected);
  EXPECT_NE(r.reason.find("does not match"), std::string::npos);
  EXPECT_EQ(applied.size(), 2u);
}

TEST(SubmapReceiver, NewSessionWithReusedIdsDoesNotCollide) {
  Bookkeeper books;
  int applied = 0;
  SubmapReceiver rx(&books, [&](ReceivedSubmap&&) { ++applied; });
  const auto a = frameFor(2, 0, 0);
  const auto b = frameFor(2, 1, 0);  // the agent reset its map: same seq and ids, new session
  EXPECT_EQ(rx.receive(a.data(), a.size(), nullptr, 1).verdict, ArrivalVerdict::kAccept);
  EXPECT_EQ(rx.receive(b.data(), b.size(), nullptr, 2).verdict, ArrivalVerdict::kAccept);
  EXPECT_EQ(applied, 2);
}

// Mutated frames from one agent, interleaved with good frames of another: no
// crash, nothing bad applied, the good agent's submaps all applied exactly once.
TEST(SubmapReceiver, FuzzedFramesDoNotDisturbOtherAgents) {
  Bookkeeper books;
  std::map<std::pair<RobotId, std::uint64_t>, int> applied;
  SubmapReceiver rx(&books, [&](ReceivedSubmap&& s) {
    ++applied[{s.robot, s.submap.header.seq}];
    EXPECT_EQ(s.submap.validate(), "");
  });
  std::vector<std::vector<std::uint8_t>> seeds;
  for (int i = 0; i < 4; ++i) seeds.push_back(frameFor(3, 0, 100 + i));
  std::mt19937_64 rng(5);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(3);
  std::uint64_t good_seq = 0;
  int iterations = 0;
  while (std::chrono::steady_clock::now() < deadline && iterations < 20000) {
    ++iterations;
    auto f = seeds[rng() % seeds.size()];
    switch (rng() % 4) {
      case 0: f[rng() % f.size()] ^= static_cast<std::uint8_t>(1u << (rng() % 8)); break;
      case 1: f.resize(rng() % f.size()); break;
      case 2: for (int k = 0; k < 8; ++k) f[rng() % f.size()] = static_cast<std::uint8_t>(rng()); break;
      default: f.insert(f.begin() + static_cast<long>(rng() % f.size()), static_cast<std::uint8_t>(rng())); break;
    }
    rx.receive(f.data(), f.size(), nullptr, iterations * 0.01);
    if (iterations % 200 == 0) {
      const auto g = frameFor(4, 0, good_seq++);
      EXPECT_EQ(rx.receive(g.data(), g.size(), nullptr, iterations * 0.01).verdict,
                ArrivalVerdict::kAccept);
    }
  }
  const auto good = books.robotOf(uuidFromSeed(4));
  ASSERT_TRUE(good.has_value());
  for (std::uint64_t s = 0; s < good_seq; ++s) EXPECT_EQ((applied[{*good, s}]), 1);
  for (const auto& [k, n] : applied) EXPECT_EQ(n, 1);
  std::printf("fuzz iterations %d, rejected %zu, good applied %llu\n", iterations,
              rx.stats().rejected, static_cast<unsigned long long>(good_seq));
}
