// The receiver's gates (admission.h): authentication before anything is
// decoded, replays acknowledged but never applied twice, per-robot quotas
// refusing without an ack (the robot resends later) and never touching the
// other robots; the server's metrics count every reason and report held bytes.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "hermes/core/crc32.h"
#include "hermes/core/frame_auth.h"
#include "hermes/core/wire_synthetic.h"
#include "hermes/server/admission.h"
#include "hermes/server/server.h"
#include "hermes/server/server_outputs.h"
#include "hermes/server/submap_receiver.h"

using namespace hermes;

namespace {

using Frame = std::vector<std::uint8_t>;

FrameKey keyOf(std::uint8_t seed) {
  FrameKey k;
  for (std::size_t i = 0; i < k.bytes.size(); ++i) k.bytes[i] = static_cast<std::uint8_t>(seed * 31 + i);
  return k;
}

Frame frameFor(std::uint64_t agent_seed, std::uint64_t seq, const FrameKey* key) {
  SyntheticSubmapOptions o;
  o.keyframes = 2;
  o.keypoints_per_keyframe = 40;
  o.landmarks = 50;
  o.seed = agent_seed * 1000 + seq;
  Submap s = makeSyntheticSubmap(o);
  s.header.agent = uuidFromSeed(agent_seed);
  s.header.session = 0;
  s.header.seq = seq;
  auto f = encodeSubmap(s, WireOptions{});
  EXPECT_TRUE(f.ok()) << f.error();
  if (!key) return *f;
  auto t = signFrame(*f, *key);
  EXPECT_TRUE(t.ok()) << t.error();
  return *t;
}

/// Recomputes the CRC of a frame changed on purpose (so that only the tag can notice).
void resealCrc(Frame* f) {
  const std::uint32_t crc = crc32(f->data() + kWireCrcOffset + 4, f->size() - kWireCrcOffset - 4,
                                  crc32(f->data(), kWireCrcOffset));
  for (int i = 0; i < 4; ++i) (*f)[kWireCrcOffset + i] = static_cast<std::uint8_t>(crc >> (8 * i));
}

/// A tagged frame whose body is garbage under a valid CRC: if it got past the
/// tag check, the decoder would call it malformed.
Frame forgedGarbage(std::uint64_t agent_seed, std::uint64_t seq) {
  Frame f = frameFor(agent_seed, seq, nullptr);
  for (std::size_t i = kWireFixedBytes; i < f.size(); ++i) f[i] = 0xee;
  resealCrc(&f);
  auto t = signFrame(f, keyOf(99));  // a key the server does not hold for this robot
  EXPECT_TRUE(t.ok());
  return *t;
}

Keyring ringWith(std::uint64_t agent_seed, const FrameKey& key) {
  Keyring ring;
  ring.add(uuidFromSeed(agent_seed), "robot" + std::to_string(agent_seed), key);
  return ring;
}

ReceiveResult send(SubmapReceiver& rx, const Frame& f, double now) {
  return rx.receive(f.data(), f.size(), nullptr, now);
}

}  // namespace

TEST(FrameAdmission, AuthenticationRejectsBeforeDecodingAndReplaysAreNotApplied) {
  const FrameKey k1 = keyOf(1);
  Keyring ring = ringWith(1, k1);
  ring.add(uuidFromSeed(2), "robot2", keyOf(2));
  Bookkeeper books;
  std::vector<ReceivedSubmap> applied;
  SubmapReceiver rx(&books, [&](ReceivedSubmap&& s) { applied.push_back(std::move(s)); }, {},
                    ReceiverGuards{&ring, nullptr});

  auto r = send(rx, frameFor(1, 0, &k1), 1.0);
  EXPECT_EQ(r.code, ReceiveCode::kAccepted) << r.reason;
  EXPECT_TRUE(r.acknowledge);

  r = send(rx, frameFor(1, 1, nullptr), 2.0);
  EXPECT_EQ(r.code, ReceiveCode::kMissingTag) << r.reason;
  EXPECT_FALSE(r.acknowledge);
  EXPECT_NE(r.reason.find("carries no tag"), std::string::npos) << r.reason;

  const FrameKey k2 = keyOf(2);
  r = send(rx, frameFor(1, 1, &k2), 3.0);  // robot 2's key on robot 1's frame
  EXPECT_EQ(r.code, ReceiveCode::kBadTag) << r.reason;
  EXPECT_FALSE(r.acknowledge);
  EXPECT_NE(r.reason.find("robot1"), std::string::npos) << r.reason;

  Frame altered = frameFor(1, 1, &k1);  // body altered in transit, CRC patched up
  altered[kWireFixedBytes + 10] ^= 0x04;
  resealCrc(&altered);
  r = send(rx, altered, 3.5);
  EXPECT_EQ(r.code, ReceiveCode::kBadTag) << r.reason;
  r = send(rx, forgedGarbage(1, 1), 4.0);
  EXPECT_EQ(r.code, ReceiveCode::kBadTag) << r.reason;  // not kMalformed: never decoded

  r = send(rx, frameFor(7, 0, &k1), 5.0);  // no key for agent 7
  EXPECT_EQ(r.code, ReceiveCode::kUnknownRobot) << r.reason;
  EXPECT_FALSE(r.acknowledge);
  EXPECT_NE(r.reason.find("unknown robot"), std::string::npos) << r.reason;

  r = send(rx, frameFor(1, 0, &k1), 6.0);  // replay of an applied (session, seq)
  EXPECT_EQ(r.code, ReceiveCode::kReplay) << r.reason;
  EXPECT_EQ(r.verdict, ArrivalVerdict::kDuplicate);
  EXPECT_TRUE(r.acknowledge);
  EXPECT_EQ(r.reason.rfind("replay: ", 0), 0u) << r.reason;

  r = send(rx, frameFor(1, 0, &k2), 7.0);  // a forged "replay" is not even acknowledged
  EXPECT_EQ(r.code, ReceiveCode::kBadTag);
  EXPECT_FALSE(r.acknowledge);

  r = send(rx, frameFor(1, 1, &k1), 8.0);  // the honest seq 1 still gets in
  EXPECT_EQ(r.code, ReceiveCode::kAccepted) << r.reason;
  ASSERT_EQ(applied.size(), 2u);
  EXPECT_EQ(applied[1].submap.header.seq, 1u);

  const ReceiverStats& st = rx.stats();
  EXPECT_EQ(st.count(ReceiveCode::kAccepted), 2u);
  EXPECT_EQ(st.count(ReceiveCode::kMissingTag), 1u);
  EXPECT_EQ(st.count(ReceiveCode::kBadTag), 4u);
  EXPECT_EQ(st.count(ReceiveCode::kUnknownRobot), 1u);
  EXPECT_EQ(st.count(ReceiveCode::kReplay), 1u);
  EXPECT_EQ(st.frames, 9u);
  EXPECT_EQ(books.robots().size(), 1u);  // nothing unauthenticated registered an agent
}

TEST(FrameAdmission, QuotaRefusesWithoutAckOtherRobotsUntouched) {
  QueueParams qp;
  qp.max_per_robot = 2;
  RobotQuotas quotas(qp);
  Bookkeeper books;
  std::vector<ReceivedSubmap> held;
  SubmapReceiver rx(
      &books,
      [&](ReceivedSubmap&& s) {
        quotas.hold(s.robot, s.bytes);
        held.push_back(std::move(s));
      },
      {}, ReceiverGuards{nullptr, [&](RobotId r, std::size_t b) { return quotas.admit(r, b); }});

  for (std::uint64_t seq = 0; seq < 2; ++seq)
    EXPECT_EQ(send(rx, frameFor(1, seq, nullptr), 1.0).code, ReceiveCode::kAccepted);
  for (std::uint64_t seq = 2; seq < 6; ++seq) {  // the flood
    auto r = send(rx, frameFor(1, seq, nullptr), 1.0 + seq);
    EXPECT_EQ(r.code, ReceiveCode::kQuota) << r.reason;
    EXPECT_FALSE(r.acknowledge);
    EXPECT_NE(r.reason.find("max_per_robot 2"), std::string::npos) << r.reason;
  }
  // A resend of something held is acknowledged, quota or not.
  EXPECT_EQ(send(rx, frameFor(1, 0, nullptr), 7.0).code, ReceiveCode::kReplay);
  // Another robot is not affected.
  for (std::uint64_t seq = 0; seq < 2; ++seq)
    EXPECT_EQ(send(rx, frameFor(2, seq, nullptr), 8.0).code, ReceiveCode::kAccepted);
  // The merger drains robot 1: its refused submaps get in on resend, nothing lost.
  for (const ReceivedSubmap& s : held) quotas.release(s.robot, s.bytes);
  held.clear();
  for (std::uint64_t seq = 2; seq < 4; ++seq)
    EXPECT_EQ(send(rx, frameFor(1, seq, nullptr), 9.0).code, ReceiveCode::kAccepted);
  EXPECT_EQ(send(rx, frameFor(1, 4, nullptr), 9.0).code, ReceiveCode::kQuota);
  const HeldLoad* l1 = quotas.load(*books.robotOf(uuidFromSeed(1)));
  ASSERT_NE(l1, nullptr);
  EXPECT_EQ(l1->submaps, 2u);
  EXPECT_EQ(l1->peak_submaps, 2u);
  EXPECT_EQ(l1->refused, 5u);
  EXPECT_EQ(rx.stats().count(ReceiveCode::kQuota), 5u);
}

TEST(FrameAdmission, ByteQuotaAlwaysAdmitsOneSubmap) {
  QueueParams qp;
  qp.max_mbytes_per_robot = 1e-6;  // 1 byte: smaller than any frame
  RobotQuotas q(qp);
  EXPECT_EQ(q.admit(0, 5000), "");  // nothing held: one submap always fits
  q.hold(0, 5000);
  const std::string why = q.admit(0, 10);
  EXPECT_NE(why.find("5000 bytes held"), std::string::npos) << why;
  EXPECT_EQ(q.admit(1, 5000), "");  // robot 1 has its own bound
  q.release(0, 5000);
  EXPECT_EQ(q.admit(0, 10), "");
  EXPECT_EQ(q.load(0)->peak_bytes, 5000u);

  QueueParams bad;
  bad.max_per_robot = 0;
  EXPECT_FALSE(bad.validate());
  auto config = Config::fromString(
      "server:\n  queue:\n    max_per_robot: 4\n    max_mbytes_per_robot: 2.5\n"
      "  auth:\n    enabled: true\n    key_dir: /k\n",
      "test");
  ASSERT_TRUE(config.ok());
  server::ServerParams p;
  ASSERT_TRUE(p.read(*config)) << p.read(*config).error();
  EXPECT_EQ(p.queue.max_per_robot, 4);
  EXPECT_DOUBLE_EQ(p.queue.max_mbytes_per_robot, 2.5);
  EXPECT_TRUE(p.auth.enabled);
  EXPECT_EQ(p.auth.key_dir, "/k");
  auto empty_dir = Config::fromString("server:\n  auth:\n    enabled: true\n    key_dir: ''\n", "t");
  ASSERT_TRUE(empty_dir.ok());
  EXPECT_FALSE(p.read(*empty_dir));
}

TEST(FrameAdmission, ServerCountsReasonsAndReportsHeldBytes) {
  server::ServerParams params;
  params.auth.enabled = true;
  params.queue.max_per_robot = 1;
  params.auth.key_dir = ::testing::TempDir() + "/hermes_no_such_keys";
  auto missing = server::Server::create(params, HERMES_SOURCE_DIR);
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.error().find("hermes_no_such_keys"), std::string::npos) << missing.error();

  const FrameKey k1 = keyOf(1);
  auto server = server::Server::create(params, HERMES_SOURCE_DIR, ringWith(1, k1));
  ASSERT_TRUE(server.ok()) << server.error();
  server::Server& s = **server;
  const Frame f0 = frameFor(1, 0, &k1), f1 = frameFor(1, 1, &k1);
  EXPECT_EQ(s.onFrame(f0.data(), f0.size(), nullptr, 1.0).code, ReceiveCode::kAccepted);
  EXPECT_EQ(s.onFrame(f1.data(), f1.size(), nullptr, 1.1).code, ReceiveCode::kQuota);
  const Frame forged = forgedGarbage(1, 1);
  EXPECT_EQ(s.onFrame(forged.data(), forged.size(), nullptr, 1.2).code, ReceiveCode::kBadTag);
  const RobotId robot = *s.bookkeeper().robotOf(uuidFromSeed(1));
  ASSERT_NE(s.heldLoad(robot), nullptr);
  EXPECT_EQ(s.heldLoad(robot)->bytes, f0.size());

  RunMetrics m = server::serverMetrics(s);
  ASSERT_EQ(m.per_agent.size(), 1u);
  EXPECT_EQ(m.per_agent[0].held_bytes, static_cast<int64_t>(f0.size()));
  EXPECT_EQ(m.per_agent[0].held_submaps, 1);
  EXPECT_EQ(m.frames_refused.at("quota"), 1);
  EXPECT_EQ(m.frames_refused.at("bad_tag"), 1);
  auto back = metricsFromJson(nlohmann::json::parse(metricsToJsonString(m)), "round trip");
  ASSERT_TRUE(back.ok()) << back.error();
  EXPECT_EQ(back->frames_refused, m.frames_refused);
  EXPECT_EQ(back->per_agent[0].held_bytes_peak, static_cast<int64_t>(f0.size()));

  s.process(2.0, -1);  // merged: nothing held, the refused submap now fits
  EXPECT_EQ(s.heldLoad(robot)->bytes, 0u);
  EXPECT_EQ(s.onFrame(f1.data(), f1.size(), nullptr, 12.0).code, ReceiveCode::kAccepted);
  EXPECT_EQ(server::serverMetrics(s).per_agent[0].held_bytes_peak, static_cast<int64_t>(f0.size()));
}
