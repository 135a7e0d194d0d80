// Relayed delivery (relay_spool.h): an origin robot's submaps through a relay's
// durable per-origin spool to a deduplicating server and the acknowledgements
// back; duplicates, a relay restart, bad input.
#include <gtest/gtest.h>

#include <filesystem>
#include <map>
#include <set>
#include <vector>

#include "hermes/agent/relay_spool.h"
#include "hermes/core/wire_format.h"
#include "hermes/core/wire_synthetic.h"

using namespace hermes;
using namespace hermes::agent;

namespace {

using Key = std::pair<std::uint32_t, std::uint64_t>;

struct Sent {
  Key key;
  std::vector<std::uint8_t> frame;
};

std::vector<std::uint8_t> frameOf(std::uint32_t session, std::uint64_t seq) {
  SyntheticSubmapOptions o;
  o.keyframes = 3;
  o.keypoints_per_keyframe = 60;
  o.landmarks = 80;
  o.seed = seq;
  Submap s = makeSyntheticSubmap(o);
  s.header.session = session;
  s.header.seq = seq;
  auto bytes = encodeSubmap(s);
  EXPECT_TRUE(bytes.ok()) << bytes.error();
  return *bytes;
}

UplinkParams spoolParams(const std::string& dir) {
  UplinkParams p;
  p.buffer.dir = dir;
  p.buffer.fsync = false;
  p.buffer.resend_timeout_s = 2.0;
  return p;
}

std::string freshDir(const std::string& name) {
  const std::string dir = ::testing::TempDir() + "/relay_spool_" + name;
  std::filesystem::remove_all(dir);
  return dir;
}

}  // namespace

TEST(RelaySpool, ExactlyOnceThroughTheRelayWithAcksBack) {
  const std::string root = freshDir("roundtrip");
  std::vector<Sent> to_relay, to_server;
  auto origin = UplinkSender::create(spoolParams(root + "/origin"),
                                     [&](std::uint32_t s, std::uint64_t q, const std::vector<std::uint8_t>& f) {
                                       to_relay.push_back({{s, q}, f});
                                     });
  ASSERT_TRUE(origin.ok()) << origin.error();
  auto relay = RelaySpool::open(root + "/relay", spoolParams(""),
                                [&](const std::string& from, std::uint32_t s, std::uint64_t q,
                                    const std::vector<std::uint8_t>& f) {
                                  EXPECT_EQ(from, "aerial_1");
                                  to_server.push_back({{s, q}, f});
                                });
  ASSERT_TRUE(relay.ok()) << relay.error();
  for (std::uint64_t seq = 1; seq <= 4; ++seq) ASSERT_TRUE(origin->submit(1, seq, frameOf(1, seq), 0.0));
  ASSERT_EQ(to_relay.size(), 4u);
  const std::size_t origin_bytes = origin->backlogBytes();
  ASSERT_GT(origin_bytes, 0u);

  // The relay spools each one and acknowledges the hop: the origin keeps them,
  // but no longer as its backlog, and does not resend them on a timeout.
  for (const Sent& s : to_relay) {
    auto offer = (*relay)->offer("aerial_1", s.key.first, s.key.second, s.frame, 1.0);
    ASSERT_TRUE(offer.ok()) << offer.error();
    EXPECT_EQ(*offer, RelaySpool::Offer::kStored);
    origin->onHandedOver(s.key.first, s.key.second, 1.1);
  }
  EXPECT_EQ(origin->backlogBytes(), 0u);
  EXPECT_EQ(origin->buffer().pendingCount(), 4u);
  // The hop acknowledgements measured the link to the relay: the origin's
  // coordinator plans with that rate (4 submaps delivered in 1.1 s).
  EXPECT_GT(origin->monitor().samples(), 0);
  EXPECT_NEAR(origin->monitor().estimate(1.1), double(origin_bytes) / 1.1, 0.5 * double(origin_bytes));
  EXPECT_EQ(origin->handedOverCount(), 4u);
  to_relay.clear();
  origin->poll(100.0);
  EXPECT_TRUE(to_relay.empty()) << "handed-over submaps were resent on a timeout";

  // A resent copy while the relay holds it is not stored twice.
  auto dup = (*relay)->offer("aerial_1", 1, 2, frameOf(1, 2), 2.0);
  ASSERT_TRUE(dup.ok());
  EXPECT_EQ(*dup, RelaySpool::Offer::kAlreadyHeld);
  EXPECT_EQ((*relay)->pendingCount("aerial_1"), 4u);

  // The relay forwards; the server applies each (session, seq) once and acknowledges.
  (*relay)->poll(2.0);
  ASSERT_EQ(to_server.size(), 4u);
  std::set<Key> applied;
  for (const Sent& s : to_server) {
    EXPECT_TRUE(applied.insert(s.key).second);
    EXPECT_EQ(s.frame, frameOf(s.key.first, s.key.second)) << "the relay changed the frame";
    EXPECT_TRUE((*relay)->onServerAck("aerial_1", s.key.first, s.key.second, 3.0));
    ASSERT_TRUE(origin->onAck(s.key.first, s.key.second, 3.5));  // passed on to the origin
  }
  EXPECT_EQ((*relay)->pendingBytes(), 0u);
  EXPECT_EQ(origin->buffer().pendingCount(), 0u);
  EXPECT_EQ(origin->handedOverCount(), 0u);
  // A duplicate acknowledgement is harmless; a late resend is answered with the ack.
  EXPECT_FALSE((*relay)->onServerAck("aerial_1", 1, 3, 4.0));
  auto late = (*relay)->offer("aerial_1", 1, 3, frameOf(1, 3), 4.0);
  ASSERT_TRUE(late.ok());
  EXPECT_EQ(*late, RelaySpool::Offer::kAlreadyAcked);
  EXPECT_EQ((*relay)->pendingCount("aerial_1"), 0u);
  const RelaySpool::OriginStats* st = (*relay)->stats("aerial_1");
  ASSERT_NE(st, nullptr);
  EXPECT_EQ(st->stored, 4u);
  EXPECT_EQ(st->duplicates, 2u);
  EXPECT_EQ(st->server_acked, 4u);
}

TEST(RelaySpool, HandedOverSubmapsAreResentAfterAReconnect) {
  const std::string root = freshDir("reconnect");
  std::vector<Sent> sent;
  auto origin = UplinkSender::create(spoolParams(root + "/origin"),
                                     [&](std::uint32_t s, std::uint64_t q, const std::vector<std::uint8_t>& f) {
                                       sent.push_back({{s, q}, f});
                                     });
  ASSERT_TRUE(origin.ok());
  ASSERT_TRUE(origin->submit(1, 1, frameOf(1, 1), 0.0));
  origin->onHandedOver(1, 1, 0.5);
  sent.clear();
  origin->poll(50.0);
  EXPECT_TRUE(sent.empty());
  origin->onReconnect();  // another route: what the relay held is sent again
  EXPECT_GT(origin->backlogBytes(), 0u);
  origin->poll(50.0);
  EXPECT_EQ(sent.size(), 1u);
}

TEST(RelaySpool, RestartedRelayKeepsAndForwardsItsSpool) {
  const std::string root = freshDir("restart");
  std::map<std::string, std::set<Key>> forwarded;
  auto forward = [&](const std::string& from, std::uint32_t s, std::uint64_t q,
                     const std::vector<std::uint8_t>&) { forwarded[from].insert({s, q}); };
  {
    auto relay = RelaySpool::open(root, spoolParams(""), forward);
    ASSERT_TRUE(relay.ok());
    for (std::uint64_t q = 1; q <= 3; ++q)
      ASSERT_TRUE((*relay)->offer("aerial_1", 2, q, frameOf(2, q), 0.0).ok());
    ASSERT_TRUE((*relay)->offer("aerial_2", 1, 7, frameOf(1, 7), 0.0).ok());
    (*relay)->onServerAck("aerial_1", 2, 1, 1.0);  // one already through
  }  // the relay process ends with three submaps unacknowledged
  forwarded.clear();
  auto relay = RelaySpool::open(root, spoolParams(""), forward);
  ASSERT_TRUE(relay.ok()) << relay.error();
  EXPECT_EQ((*relay)->origins(), (std::vector<std::string>{"aerial_1", "aerial_2"}));
  EXPECT_EQ((*relay)->pendingCount("aerial_1"), 2u);
  EXPECT_EQ((*relay)->pendingCount("aerial_2"), 1u);
  (*relay)->poll(2.0);
  EXPECT_EQ(forwarded["aerial_1"], (std::set<Key>{{2, 2}, {2, 3}}));
  EXPECT_EQ(forwarded["aerial_2"], (std::set<Key>{{1, 7}}));
  // The restarted relay still stores a held submap only once.
  auto again = (*relay)->offer("aerial_1", 2, 3, frameOf(2, 3), 3.0);
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(*again, RelaySpool::Offer::kAlreadyHeld);
}

TEST(RelaySpool, RefusesBadInputWithAReason) {
  const std::string root = freshDir("bad");
  int forwards = 0;
  auto relay = RelaySpool::open(root, spoolParams(""),
                                [&](const std::string&, std::uint32_t, std::uint64_t,
                                    const std::vector<std::uint8_t>&) { ++forwards; });
  ASSERT_TRUE(relay.ok());
  auto bad_name = (*relay)->offer("../etc", 1, 1, frameOf(1, 1), 0.0);
  ASSERT_FALSE(bad_name.ok());
  EXPECT_NE(bad_name.error().find("../etc"), std::string::npos) << bad_name.error();
  std::vector<std::uint8_t> damaged = frameOf(1, 2);
  damaged[damaged.size() / 2] ^= 0x5a;
  auto crc = (*relay)->offer("aerial_1", 1, 2, damaged, 0.0);
  ASSERT_FALSE(crc.ok());
  EXPECT_NE(crc.error().find("aerial_1"), std::string::npos) << crc.error();
  auto routing = (*relay)->offer("aerial_1", 1, 9, frameOf(1, 3), 0.0);
  ASSERT_FALSE(routing.ok());
  EXPECT_NE(routing.error().find("1/9"), std::string::npos) << routing.error();
  (*relay)->poll(1.0);
  EXPECT_EQ(forwards, 0);
  EXPECT_EQ((*relay)->pendingBytes(), 0u);
  EXPECT_FALSE(RelaySpool::open("", spoolParams(""), nullptr).ok());
}
