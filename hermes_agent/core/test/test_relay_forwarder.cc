// The relay's forwarding on a link without shares (relay_forwarder.h): only
// the robots it serves, each paced at its coordinator's rate with the
// relay.min_mbitps floor, acknowledgements freeing the spool, a restart
// forwarding what was held; the robot list of the launch argument.
#include <gtest/gtest.h>

#include <filesystem>
#include <map>
#include <vector>

#include "hermes/agent/relay_forwarder.h"
#include "hermes/core/wire_format.h"
#include "hermes/core/wire_synthetic.h"

using namespace hermes;
using namespace hermes::agent;

namespace {

struct Forwarded {
  std::string origin;
  std::uint32_t session;
  std::uint64_t seq;
  std::size_t bytes;
  double t;
};

std::vector<std::uint8_t> frameOf(const std::string& robot, std::uint64_t seq, int landmarks = 80) {
  SyntheticSubmapOptions o;
  o.keyframes = 3;
  o.keypoints_per_keyframe = 60;
  o.landmarks = landmarks;
  o.seed = seq;
  Submap s = makeSyntheticSubmap(o);
  s.header.agent = agentUuid(robot);
  s.header.session = 1;
  s.header.seq = seq;
  auto bytes = encodeSubmap(s);
  EXPECT_TRUE(bytes.ok()) << bytes.error();
  return *bytes;
}

UplinkParams spoolParams() {
  UplinkParams p;
  p.buffer.fsync = false;
  p.buffer.resend_timeout_s = 1000.0;  // no resends: the pace alone decides
  return p;
}

std::string freshDir(const std::string& name) {
  const std::string dir = ::testing::TempDir() + "/relay_forwarder_" + name;
  std::filesystem::remove_all(dir);
  return dir;
}

struct Relay {
  std::vector<Forwarded> out;
  double now = 0;
  std::unique_ptr<RelayForwarder> f;
  Relay(const std::string& dir, const std::vector<std::string>& origins, RelayParams rp = {}) {
    auto opened = RelayForwarder::open(
        dir, origins, rp, spoolParams(), 0.5,
        [this](const std::string& o, std::uint32_t session, std::uint64_t seq,
               const std::vector<std::uint8_t>& frame) {
          out.push_back({o, session, seq, frame.size(), now});
        });
    EXPECT_TRUE(opened.ok()) << opened.error();
    if (opened.ok()) f = std::move(*opened);
  }
  /// Polls every 50 ms until `until`.
  void run(double until, double uplink_Bps) {
    for (; now <= until + 1e-9; now += 0.05) f->poll(now, uplink_Bps);
  }
  double bytes(const std::string& origin, double until) const {
    double b = 0;
    for (const Forwarded& x : out)
      if (x.origin == origin && x.t <= until + 1e-9) b += static_cast<double>(x.bytes);
    return b;
  }
};

}  // namespace

TEST(RelayForwarder, ParsesTheRobotListOfTheLaunchArgument) {
  auto two = parseRobotList("uav1, uav2");
  ASSERT_TRUE(two.ok()) << two.error();
  EXPECT_EQ(*two, (std::vector<std::string>{"uav1", "uav2"}));
  auto none = parseRobotList("  ");
  ASSERT_TRUE(none.ok());
  EXPECT_TRUE(none->empty());
  auto empty_name = parseRobotList("uav1,,uav2");
  ASSERT_FALSE(empty_name.ok());
  EXPECT_NE(empty_name.error().find("not usable"), std::string::npos) << empty_name.error();
  auto twice = parseRobotList("uav1,uav1");
  ASSERT_FALSE(twice.ok());
  EXPECT_NE(twice.error().find("uav1 named twice"), std::string::npos) << twice.error();
  EXPECT_FALSE(parseRobotList("uav/1").ok());
}

TEST(RelayForwarder, TakesOnlyTheRobotsItServesAndTheirOwnFrames) {
  Relay r(freshDir("serves"), {"uav1"});
  ASSERT_TRUE(r.f);
  auto other = r.f->offer("uav2", 1, 0, frameOf("uav2", 0), 0.0);
  ASSERT_FALSE(other.ok());
  EXPECT_NE(other.error().find("not a relay for uav2"), std::string::npos) << other.error();
  auto forged = r.f->offer("uav1", 1, 0, frameOf("uav2", 0), 0.0);  // uav2's frame as uav1's
  ASSERT_FALSE(forged.ok());
  EXPECT_NE(forged.error().find("belongs to agent"), std::string::npos) << forged.error();
  EXPECT_EQ(r.f->originOfUuid(toString(agentUuid("uav1"))), "uav1");
  EXPECT_EQ(r.f->originOfUuid(toString(agentUuid("uav2"))), "");
  auto ok = r.f->offer("uav1", 1, 0, frameOf("uav1", 0), 0.0);
  ASSERT_TRUE(ok.ok()) << ok.error();
  EXPECT_EQ(*ok, RelaySpool::Offer::kStored);
}

// Through the relay and back: stored once, forwarded, freed by the server's
// acknowledgement, a late copy answered with that acknowledgement; a relay
// restarted before the server answered forwards what it held.
TEST(RelayForwarder, ExactlyOnceAndARestartedRelayForwardsItsSpool) {
  const std::string dir = freshDir("restart");
  {
    Relay r(dir, {"uav1"});
    ASSERT_TRUE(r.f);
    for (std::uint64_t seq = 0; seq < 3; ++seq) {
      auto o = r.f->offer("uav1", 1, seq, frameOf("uav1", seq), 0.0);
      ASSERT_TRUE(o.ok()) << o.error();
      EXPECT_EQ(*o, RelaySpool::Offer::kStored);
    }
    auto again = r.f->offer("uav1", 1, 1, frameOf("uav1", 1), 0.1);
    ASSERT_TRUE(again.ok());
    EXPECT_EQ(*again, RelaySpool::Offer::kAlreadyHeld);
    r.run(2.0, 1e7);
    ASSERT_EQ(r.out.size(), 3u);  // each once, the duplicate not
    EXPECT_TRUE(r.f->onServerAck("uav1", 1, 0, 2.0));
    EXPECT_FALSE(r.f->onServerAck("uav1", 1, 0, 2.0));  // a duplicate acknowledgement
    auto late = r.f->offer("uav1", 1, 0, frameOf("uav1", 0), 2.1);
    ASSERT_TRUE(late.ok());
    EXPECT_EQ(*late, RelaySpool::Offer::kAlreadyAcked);
    const auto states = r.f->states();
    ASSERT_EQ(states.size(), 1u);
    EXPECT_EQ(states[0].stats.stored, 3u);
    EXPECT_EQ(states[0].stats.duplicates, 2u);
    EXPECT_EQ(states[0].pending, 2u);
    EXPECT_EQ(states[0].forwarded, 3u);
  }
  Relay restarted(dir, {"uav1"});  // seq 1 and 2 were never acknowledged
  ASSERT_TRUE(restarted.f);
  restarted.run(1.0, 1e7);
  ASSERT_EQ(restarted.out.size(), 2u);
  EXPECT_EQ(restarted.out[0].seq, 1u);
  EXPECT_EQ(restarted.out[1].seq, 2u);
  EXPECT_TRUE(restarted.f->onServerAck("uav1", 1, 1, 1.0));
  EXPECT_TRUE(restarted.f->onServerAck("uav1", 1, 2, 1.0));
  EXPECT_EQ(restarted.f->states()[0].pending, 0u);
}

// In an outage of the relay's uplink estimate (0) a relayed robot still gets
// relay.min_mbitps: the bytes forwarded follow 125 kB/s within one frame.
TEST(RelayForwarder, PacesEachRelayedRobotAtItsFloorWhenTheUplinkIsUnknown) {
  Relay r(freshDir("floor"), {"uav1"});
  ASSERT_TRUE(r.f);
  std::size_t total = 0, biggest = 0;
  for (std::uint64_t seq = 0; seq < 40; ++seq) {
    auto f = frameOf("uav1", seq, 400);
    total += f.size();
    biggest = std::max(biggest, f.size());
    ASSERT_TRUE(r.f->offer("uav1", 1, seq, std::move(f), 0.0).ok());
  }
  const double rate = RelayParams{}.minBps();
  ASSERT_GT(static_cast<double>(total), 4 * rate) << "too little data to see the pace";
  r.run(3.0, 0.0);
  for (double t : {1.0, 2.0, 3.0}) {
    EXPECT_LE(r.bytes("uav1", t), rate * t + static_cast<double>(biggest)) << t;
    EXPECT_GE(r.bytes("uav1", t), rate * t - static_cast<double>(biggest)) << t;
  }
  EXPECT_NEAR(r.f->states()[0].rate_Bps, rate, 1e-6);
}

// Two relayed robots and the relay's own map share a known uplink: each relayed
// robot gets its floor plus its weight of the rest, the own map what is left
// (its weight of the rest), so the paces add up to the link.
TEST(RelayForwarder, SplitsAKnownUplinkByCredibilityAboveTheFloors) {
  Relay r(freshDir("split"), {"uav1", "uav2"});
  ASSERT_TRUE(r.f);
  for (std::uint64_t seq = 0; seq < 4; ++seq) {
    ASSERT_TRUE(r.f->offer("uav1", 1, seq, frameOf("uav1", seq, 400), 0.1 * double(seq)).ok());
    ASSERT_TRUE(r.f->offer("uav2", 1, seq, frameOf("uav2", seq, 80), 0.1 * double(seq)).ok());
    r.f->onOwnFrame(1, seq, frameOf("ugv1", seq, 200), 0.1 * double(seq));
  }
  const double link = 1e6;  // [byte/s]
  r.now = 1.0;
  r.f->poll(1.0, link);
  const auto s = r.f->states();
  ASSERT_EQ(s.size(), 2u);
  const double floor = RelayParams{}.minBps();
  double relayed = 0, weights = 0;
  for (const auto& o : s) {
    EXPECT_GE(o.rate_Bps, floor) << o.origin;
    EXPECT_NEAR(o.rate_Bps, floor + o.weight * (link - 2 * floor), 1e-6) << o.origin;
    relayed += o.rate_Bps;
    weights += o.weight;
  }
  EXPECT_GE(1 - weights, RelayParams{}.own_min_share - 1e-9);  // the own map's share
  EXPECT_NEAR(relayed + (1 - weights) * (link - 2 * floor), link, 1e-6);
}
