#include <gtest/gtest.h>

#include "hermes/server/bookkeeper.h"

using namespace hermes;

namespace {

SubmapArrival arrival(const Uuid& agent, std::uint32_t session, std::uint64_t seq,
                      std::size_t keyframes = 5, std::size_t bytes = 1000) {
  SubmapArrival a;
  a.header.agent = agent;
  a.header.session = session;
  a.header.seq = seq;
  a.bytes = bytes;
  a.keyframes = keyframes;
  a.landmarks = 100;
  a.observations = 300;
  return a;
}

}  // namespace

TEST(Bookkeeper, RegistrationGivesStableIdsAcrossReconnects) {
  Bookkeeper bk;
  const Uuid a = uuidFromSeed(1), b = uuidFromSeed(2);
  auto ra = bk.registerAgent(a, 0.0, "alpha");
  auto rb = bk.registerAgent(b, 0.0);
  ASSERT_TRUE(ra.ok() && rb.ok());
  EXPECT_EQ(*ra, 0u);
  EXPECT_EQ(*rb, 1u);
  auto again = bk.registerAgent(a, 50.0);  // reconnect
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(*again, 0u);
  EXPECT_EQ(bk.stats(0)->name, "alpha");
  EXPECT_EQ(bk.robots().size(), 2u);
  EXPECT_FALSE(bk.registerAgent(Uuid{}, 0.0).ok());
  // A submap after reconnect keeps the robot id.
  ArrivalDecision d = bk.onArrival(arrival(b, 0, 0), 60.0);
  EXPECT_EQ(d.verdict, ArrivalVerdict::kAccept);
  EXPECT_EQ(d.robot, 1u);
  EXPECT_FALSE(d.new_agent);
}

TEST(Bookkeeper, DuplicatesAndOutOfOrderSeqs) {
  Bookkeeper bk;
  const Uuid a = uuidFromSeed(7);
  EXPECT_EQ(bk.onArrival(arrival(a, 0, 0), 1.0).verdict, ArrivalVerdict::kAccept);
  EXPECT_EQ(bk.onArrival(arrival(a, 0, 2), 2.0).verdict, ArrivalVerdict::kAccept);  // 1 is late
  EXPECT_EQ(bk.stats(0)->submaps_missing, 1u);
  EXPECT_NEAR(bk.stats(0)->successRate(), 2.0 / 3.0, 1e-12);
  ArrivalDecision dup = bk.onArrival(arrival(a, 0, 2), 3.0);  // resend after a lost ack
  EXPECT_EQ(dup.verdict, ArrivalVerdict::kDuplicate);
  EXPECT_TRUE(dup.acknowledge);
  EXPECT_NE(dup.reason.find(toString(a)), std::string::npos) << dup.reason;
  EXPECT_EQ(bk.onArrival(arrival(a, 0, 1), 4.0).verdict, ArrivalVerdict::kAccept);  // fills the gap
  EXPECT_EQ(bk.stats(0)->submaps_missing, 0u);
  EXPECT_EQ(bk.onArrival(arrival(a, 0, 1), 5.0).verdict, ArrivalVerdict::kDuplicate);
  const AgentStats& s = *bk.stats(0);
  EXPECT_EQ(s.submaps_received, 5u);
  EXPECT_EQ(s.submaps_accepted, 3u);
  EXPECT_EQ(s.submaps_duplicate, 2u);
  EXPECT_EQ(s.bytes_received, 5000u);
  EXPECT_EQ(s.bytes_accepted, 3000u);
  EXPECT_EQ(s.keyframes, 15u);
  EXPECT_DOUBLE_EQ(s.first_time, 1.0);
  EXPECT_DOUBLE_EQ(s.last_time, 5.0);
  EXPECT_DOUBLE_EQ(s.bytesPerSecond(), 3000.0 / 4.0);
  EXPECT_DOUBLE_EQ(s.observationsPerLandmark(), 3.0);
  EXPECT_DOUBLE_EQ(s.successRate(), 1.0);

  EXPECT_TRUE(bk.markApplied(0, 0, 1).ok());
  EXPECT_FALSE(bk.markApplied(0, 0, 1).ok());   // applied twice
  EXPECT_FALSE(bk.markApplied(0, 0, 9).ok());   // never accepted
  EXPECT_FALSE(bk.markApplied(5, 0, 0).ok());   // unknown robot
  EXPECT_EQ(bk.stats(0)->submaps_applied, 1u);
}

TEST(Bookkeeper, NewSessionAfterResetKeepsOldDataAndSeparatesKeys) {
  BookkeeperParams p;
  p.stale_after_s = 30.0;
  Bookkeeper bk(p);
  const Uuid a = uuidFromSeed(3);
  ArrivalDecision d0 = bk.onArrival(arrival(a, 0, 0), 0.0);
  EXPECT_TRUE(d0.new_session);
  EXPECT_EQ(bk.onArrival(arrival(a, 0, 1), 5.0).verdict, ArrivalVerdict::kAccept);
  // The agent resets: session 1, seq and keyframe ids start again at 0.
  ArrivalDecision d1 = bk.onArrival(arrival(a, 1, 0), 10.0);
  EXPECT_EQ(d1.verdict, ArrivalVerdict::kAccept);
  EXPECT_TRUE(d1.new_session);
  EXPECT_EQ(d1.robot, d0.robot);
  EXPECT_EQ(bk.stats(0)->current_session, 1u);
  EXPECT_EQ(bk.stats(0)->sessions.size(), 2u);
  EXPECT_EQ(bk.stats(0)->sessions.at(0).submaps_accepted, 2u);
  const KeyframeKey old_kf = bk.key(0, 0, 4), new_kf = bk.key(0, 1, 4);
  EXPECT_FALSE(old_kf == new_kf);
  EXPECT_TRUE(old_kf < new_kf);
  // seq 1 of session 0 was already accepted; seq 1 of session 1 is new.
  EXPECT_EQ(bk.onArrival(arrival(a, 1, 1), 12.0).verdict, ArrivalVerdict::kAccept);
  // A late spool resend of session 0 within the grace period is still data...
  EXPECT_EQ(bk.onArrival(arrival(a, 0, 2), 20.0).verdict, ArrivalVerdict::kAccept);
  EXPECT_EQ(bk.stats(0)->current_session, 1u);
  // ...after it the old session is stale (acknowledged, not applied).
  ArrivalDecision st = bk.onArrival(arrival(a, 0, 3), 45.0);
  EXPECT_EQ(st.verdict, ArrivalVerdict::kStale);
  EXPECT_TRUE(st.acknowledge);
  EXPECT_NE(st.reason.find("session 0"), std::string::npos) << st.reason;
  EXPECT_EQ(bk.stats(0)->submaps_stale, 1u);
  // A duplicate of the old session is still reported as a duplicate.
  EXPECT_EQ(bk.onArrival(arrival(a, 0, 0), 46.0).verdict, ArrivalVerdict::kDuplicate);
}

TEST(Bookkeeper, UnknownAgentsWhenRegistrationIsRequired) {
  auto cfg = Config::fromString(
      "server:\n  bookkeeper:\n    require_registration: true\n    anchor_min_keyframes: 10\n",
      "bk.yaml");
  ASSERT_TRUE(cfg.ok());
  BookkeeperParams p;
  ASSERT_TRUE(p.read(*cfg).ok());
  EXPECT_TRUE(p.require_registration);
  EXPECT_EQ(p.anchor_min_keyframes, 10);
  Bookkeeper bk(p);
  const Uuid stranger = uuidFromSeed(99);
  ArrivalDecision d = bk.onArrival(arrival(stranger, 0, 0), 0.0);
  EXPECT_EQ(d.verdict, ArrivalVerdict::kRejected);
  EXPECT_FALSE(d.acknowledge);
  EXPECT_NE(d.reason.find(toString(stranger)), std::string::npos) << d.reason;
  EXPECT_TRUE(bk.robots().empty());
  ASSERT_TRUE(bk.registerAgent(stranger, 1.0).ok());
  EXPECT_EQ(bk.onArrival(arrival(stranger, 0, 0), 2.0).verdict, ArrivalVerdict::kAccept);
  // Implicit registration (default): the first submap registers the agent.
  Bookkeeper open;
  ArrivalDecision o = open.onArrival(arrival(stranger, 0, 0), 0.0);
  EXPECT_EQ(o.verdict, ArrivalVerdict::kAccept);
  EXPECT_TRUE(o.new_agent);
  // A nil uuid is always rejected.
  EXPECT_EQ(open.onArrival(arrival(Uuid{}, 0, 0), 0.0).verdict, ArrivalVerdict::kRejected);
  BookkeeperParams bad;
  bad.anchor_min_keyframes = -1;
  EXPECT_FALSE(bad.validate().ok());
}

// One robot that stays small (stopped early, or a lean link) must not keep every
// other robot out of the global map: a loop between qualified robots, or the wait,
// fixes the world among the qualified ones; a negative wait keeps the old rule.
TEST(Bookkeeper, ASmallRobotDoesNotBlockTheWorldFrame) {
  const Uuid a = uuidFromSeed(20), b = uuidFromSeed(21), c = uuidFromSeed(22);
  std::map<RobotId, double> cred = {{0, 0.4}, {1, 0.9}, {2, 2.0}};
  auto credibility = [&](RobotId r) { return cred.at(r); };
  auto feed = [&](Bookkeeper* bk, double t0) {  // a and b reach 12 keyframes, c stays at 3
    for (std::uint64_t seq = 0; seq < 3; ++seq) {
      bk->onArrival(arrival(a, 0, seq, 4), t0 + seq);
      bk->onArrival(arrival(b, 0, seq, 4), t0 + seq);
    }
    bk->onArrival(arrival(c, 0, 0, 3), t0);
  };
  BookkeeperParams bp;
  bp.anchor_min_keyframes = 10;
  bp.anchor_wait_s = 30;
  {  // a loop ties agent 0 to the small agent 2: agent 0 is the only tied qualified one
    Bookkeeper bk(bp);
    feed(&bk, 0);
    EXPECT_FALSE(bk.selectWorld(credibility).has_value());
    EXPECT_FALSE(bk.selectWorld(credibility, [](RobotId) { return std::size_t{1}; }).has_value());
    auto world = bk.selectWorld(credibility, [](RobotId r) { return std::size_t{r == 1 ? 1 : 2}; });
    ASSERT_TRUE(world.has_value());
    EXPECT_EQ(*world, 0u);  // c is more credible but has too few keyframes; b is not tied
  }
  {  // no loop: the wait runs from the first time a qualified agent was seen
    Bookkeeper bk(bp);
    feed(&bk, 0);
    EXPECT_FALSE(bk.selectWorld(credibility).has_value());  // clock 2 s: starts the wait
    bk.onArrival(arrival(a, 0, 3, 4), 31.0);
    EXPECT_FALSE(bk.selectWorld(credibility).has_value());  // 29 s waited
    bk.onArrival(arrival(a, 0, 4, 4), 32.5);
    auto world = bk.selectWorld(credibility);
    ASSERT_TRUE(world.has_value());
    EXPECT_EQ(*world, 1u);  // the most credible qualified agent
    EXPECT_FALSE(bk.anchored(2));
  }
  {  // a negative wait waits for every agent
    BookkeeperParams strict = bp;
    strict.anchor_wait_s = -1;
    Bookkeeper bk(strict);
    feed(&bk, 0);
    bk.onArrival(arrival(a, 0, 3, 4), 500.0);
    EXPECT_FALSE(bk.selectWorld(credibility).has_value());
    bk.onArrival(arrival(c, 0, 1, 7), 501.0);
    auto world = bk.selectWorld(credibility);
    ASSERT_TRUE(world.has_value());
    EXPECT_EQ(*world, 2u);
  }
}

// Robots that meet each other define the world, not a more credible one that
// meets no one yet: fixing the world on robot c as soon as all three qualified
// left a and b (tied by 59 loops) out of the map of a 30-s demo run.
TEST(Bookkeeper, TheWorldIsInTheLargestGroupThatLoopsTie) {
  const Uuid a = uuidFromSeed(30), b = uuidFromSeed(31), c = uuidFromSeed(32);
  std::map<RobotId, double> cred = {{0, 0.4}, {1, 0.9}, {2, 2.0}};
  auto credibility = [&](RobotId r) { return cred.at(r); };
  BookkeeperParams bp;
  bp.anchor_min_keyframes = 10;
  bp.anchor_wait_s = 30;
  auto feed = [&](Bookkeeper* bk) {  // all three qualify at 2 s
    for (std::uint64_t seq = 0; seq < 3; ++seq)
      for (const Uuid& u : {a, b, c}) bk->onArrival(arrival(u, 0, seq, 4), seq);
  };
  const auto alone = [](RobotId) { return std::size_t{1}; };
  const auto a_meets_b = [](RobotId r) { return std::size_t{r == 2 ? 1 : 2}; };
  {
    Bookkeeper bk(bp);
    feed(&bk);
    EXPECT_FALSE(bk.selectWorld(credibility, alone).has_value());  // all qualified, nobody met yet
    auto world = bk.selectWorld(credibility, a_meets_b);
    ASSERT_TRUE(world.has_value());
    EXPECT_EQ(*world, 1u);  // b: the more credible of the pair; c is alone
  }
  {  // nobody meets: after the wait, the most credible
    Bookkeeper bk(bp);
    feed(&bk);
    EXPECT_FALSE(bk.selectWorld(credibility, alone).has_value());
    bk.onArrival(arrival(a, 0, 3, 4), 33.0);
    auto world = bk.selectWorld(credibility, alone);
    ASSERT_TRUE(world.has_value());
    EXPECT_EQ(*world, 2u);
  }
  {  // a single robot defines the world as soon as it qualifies
    Bookkeeper bk(bp);
    for (std::uint64_t seq = 0; seq < 3; ++seq) bk.onArrival(arrival(a, 0, seq, 4), seq);
    auto world = bk.selectWorld(credibility, alone);
    ASSERT_TRUE(world.has_value());
    EXPECT_EQ(*world, 0u);
  }
}

TEST(Bookkeeper, WorldFrameAfterThirtyKeyframesEachThenLoopsAnchorOthers) {
  BookkeeperParams bp;
  bp.anchor_min_keyframes = 30;
  bp.anchor_wait_s = -1;  // the oldest rule: once every agent qualified
  Bookkeeper bk(bp);
  const Uuid a = uuidFromSeed(10), b = uuidFromSeed(11), c = uuidFromSeed(12);
  std::map<RobotId, double> cred = {{0, 0.4}, {1, 0.9}, {2, 0.6}};
  auto credibility = [&](RobotId r) { return cred.at(r); };
  std::uint64_t seq = 0;
  // a and b reach 30 keyframes, c only 28: no world yet.
  for (int i = 0; i < 3; ++i) {
    bk.onArrival(arrival(a, 0, seq, 10), i);
    bk.onArrival(arrival(b, 0, seq, 10), i);
    bk.onArrival(arrival(c, 0, seq, 10 - (i == 2 ? 2 : 0)), i);
    ++seq;
  }
  EXPECT_FALSE(bk.selectWorld(credibility).has_value());
  EXPECT_FALSE(bk.worldAgent().has_value());
  Status early = bk.markAnchored(0, SE3::identity());
  ASSERT_FALSE(early.ok());
  EXPECT_NE(early.error().find(toString(a)), std::string::npos) << early.error();
  bk.onArrival(arrival(c, 0, seq, 2), 3.0);  // c reaches 30
  auto world = bk.selectWorld(credibility);
  ASSERT_TRUE(world.has_value());
  EXPECT_EQ(*world, 1u);  // most credible
  EXPECT_TRUE(bk.anchored(1));
  EXPECT_FALSE(bk.anchored(0));
  EXPECT_FALSE(bk.T_W_A(0).has_value());
  // The world does not move afterwards, even if credibilities change.
  cred[0] = 5.0;
  EXPECT_EQ(*bk.selectWorld(credibility), 1u);
  // A verified loop ties agent 0 to the world.
  const SE3 T_W_A0(expSO3(Vec3(0, 0, 0.3)), Vec3(1, 2, 0));
  ASSERT_TRUE(bk.markAnchored(0, T_W_A0).ok());
  ASSERT_TRUE(bk.T_W_A(0).has_value());
  EXPECT_NEAR((bk.T_W_A(0)->translation() - Vec3(1, 2, 0)).norm(), 0, 1e-12);
  EXPECT_FALSE(bk.markAnchored(1, T_W_A0).ok());  // the world agent stays at identity
  Status unknown = bk.markAnchored(7, T_W_A0);
  EXPECT_FALSE(unknown.ok());
  EXPECT_NE(unknown.error().find("7"), std::string::npos);
}
