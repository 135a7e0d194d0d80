// Registration and re-localisation in the bookkeeper (bookkeeper.h): a robot
// that reconnects keeps its session and anchoring; one that restarts (a new
// session) is anchored again only by loops, counted as re-localised, or after
// server.relocalisation_timeout_s reported as a new robot; always under its
// robot id. The state survives a checkpoint.
#include <gtest/gtest.h>

#include "hermes/server/byte_codec.h"
#include "hermes/server/server.h"

using namespace hermes;

namespace {

SubmapArrival arrival(const Uuid& agent, std::uint32_t session, std::uint64_t seq) {
  SubmapArrival a;
  a.header.agent = agent;
  a.header.session = session;
  a.header.seq = seq;
  a.bytes = 1000;
  a.keyframes = 20;
  a.landmarks = 100;
  a.observations = 300;
  return a;
}

BookkeeperParams params(double relocalisation_timeout_s) {
  BookkeeperParams p;
  p.relocalisation_timeout_s = relocalisation_timeout_s;
  return p;
}

/// Robots 0 (the world) and 1 (anchored by loops at T_W_A1), session 1 each, at t 0..2 s.
struct TwoRobots {
  const Uuid a = uuidFromSeed(41), b = uuidFromSeed(42);
  const SE3 T_W_A1{expSO3(Vec3(0, 0, 0.4)), Vec3(3, -1, 0.5)};
  Bookkeeper bk;
  explicit TwoRobots(double relocalisation_timeout_s = 60) : bk(params(relocalisation_timeout_s)) {
    for (std::uint64_t seq = 0; seq < 2; ++seq) {
      EXPECT_EQ(bk.onArrival(arrival(a, 1, seq), double(seq)).verdict, ArrivalVerdict::kAccept);
      EXPECT_EQ(bk.onArrival(arrival(b, 1, seq), double(seq) + 0.5).verdict, ArrivalVerdict::kAccept);
    }
    // A loop ties the two (as markAnchored below says): the world is fixed.
    EXPECT_EQ(bk.selectWorld([](RobotId r) { return r == 0 ? 1.0 : 0.5; }, [](RobotId) { return std::size_t{2}; }),
              std::optional<RobotId>(0));
    EXPECT_TRUE(bk.markAnchored(1, T_W_A1));
  }
};

}  // namespace

TEST(Relocalisation, ReconnectAfterAnOutageKeepsSessionIdAndAnchoring) {
  TwoRobots f;
  // 40 s without a word, then the same session goes on (and resends one it had sent).
  const ArrivalDecision d = f.bk.onArrival(arrival(f.b, 1, 2), 42.0);
  EXPECT_EQ(d.verdict, ArrivalVerdict::kAccept);
  EXPECT_FALSE(d.new_session);
  EXPECT_FALSE(d.new_agent);
  EXPECT_EQ(d.robot, 1u);
  EXPECT_EQ(f.bk.onArrival(arrival(f.b, 1, 1), 42.1).verdict, ArrivalVerdict::kDuplicate);
  EXPECT_EQ(f.bk.registerAgent(f.b, 43.0).value(), 1u);
  ASSERT_TRUE(f.bk.T_W_A(1).has_value());
  EXPECT_NEAR((f.bk.T_W_A(1)->translation() - f.T_W_A1.translation()).norm(), 0, 1e-12);
  const AgentStats* s = f.bk.stats(1);
  EXPECT_EQ(s->sessions.size(), 1u);
  EXPECT_EQ(s->sessions.at(1).anchored_by, SessionAnchor::kLoop);
  EXPECT_EQ(s->relocalisedSessions(), 0);  // its first session: anchored, not re-localised
  EXPECT_TRUE(f.bk.checkRelocalisation(500.0).empty());
  EXPECT_EQ(f.bk.robots().size(), 2u);
}

TEST(Relocalisation, NewSessionIsAnchoredOnlyByLoopsAndThenCountedReLocalised) {
  TwoRobots f;
  const ArrivalDecision d = f.bk.onArrival(arrival(f.b, 2, 0), 10.0);  // robot 1 reset its map
  EXPECT_EQ(d.verdict, ArrivalVerdict::kAccept);
  EXPECT_TRUE(d.new_session);
  EXPECT_EQ(d.robot, 1u);
  // It does not know where it is: not anchored until loops tie it.
  EXPECT_FALSE(f.bk.anchored(1));
  EXPECT_FALSE(f.bk.T_W_A(1).has_value());
  EXPECT_EQ(f.bk.stats(1)->sessions.at(2).anchored_by, SessionAnchor::kNone);
  EXPECT_FALSE(f.bk.markSessionAnchored(1, 2, SessionAnchor::kWorld, SE3::identity()));
  const SE3 T_W_A1b(expSO3(Vec3(0, 0.1, -0.3)), Vec3(-2, 4, 0));
  ASSERT_TRUE(f.bk.markSessionAnchored(1, 2, SessionAnchor::kLoop, T_W_A1b));
  EXPECT_TRUE(f.bk.anchored(1));
  EXPECT_NEAR((f.bk.T_W_A(1)->translation() - T_W_A1b.translation()).norm(), 0, 1e-12);
  const AgentStats* s = f.bk.stats(1);
  EXPECT_TRUE(s->sessions.at(2).relocalised);
  EXPECT_EQ(s->sessions.at(2).anchored_by, SessionAnchor::kLoop);
  EXPECT_DOUBLE_EQ(s->sessions.at(2).anchored_at, 10.0);
  EXPECT_EQ(s->relocalisedSessions(), 1);
  EXPECT_EQ(s->newRobotSessions(), 0);
  // Anchored in time: never reported as a new robot; the id stays the robot's.
  EXPECT_TRUE(f.bk.checkRelocalisation(1000.0).empty());
  EXPECT_EQ(f.bk.robots().size(), 2u);
  EXPECT_EQ(f.bk.robotOf(f.b), std::optional<RobotId>(1));
  // Old-session frames still in its spool: applied within the grace, stale after it.
  EXPECT_EQ(f.bk.onArrival(arrival(f.b, 1, 2), 12.0).verdict, ArrivalVerdict::kAccept);
  EXPECT_EQ(f.bk.onArrival(arrival(f.b, 1, 3), 10.0 + 61.0).verdict, ArrivalVerdict::kStale);
  EXPECT_EQ(f.bk.stats(1)->current_session, 2u);
}

TEST(Relocalisation, TheWorldRobotsNewSessionIsNotPutAtTheOrigin) {
  TwoRobots f;
  f.bk.onArrival(arrival(f.a, 2, 0), 10.0);
  EXPECT_EQ(f.bk.worldAgent(), std::optional<RobotId>(0));  // the world frame stays
  EXPECT_FALSE(f.bk.anchored(0));
  // The new session cannot take over the world frame; loops place it anywhere.
  EXPECT_FALSE(f.bk.markSessionAnchored(0, 2, SessionAnchor::kWorld, SE3::identity()));
  const SE3 T_W_A0b(expSO3(Vec3(0.2, 0, 0)), Vec3(5, 5, 1));
  ASSERT_TRUE(f.bk.markSessionAnchored(0, 2, SessionAnchor::kLoop, T_W_A0b));
  EXPECT_TRUE(f.bk.anchored(0));
  EXPECT_EQ(f.bk.stats(0)->sessions.at(1).anchored_by, SessionAnchor::kWorld);
  EXPECT_EQ(f.bk.stats(0)->relocalisedSessions(), 1);
  // The world session itself must stay at identity.
  EXPECT_FALSE(f.bk.markSessionAnchored(0, 1, SessionAnchor::kLoop, T_W_A0b));
  EXPECT_FALSE(f.bk.markSessionAnchored(0, 7, SessionAnchor::kLoop, T_W_A0b));  // no such session
}

TEST(Relocalisation, ARobotResetBeforeTheWorldIsFixedDefinesItWithItsFirstSession) {
  Bookkeeper bk;
  const Uuid a = uuidFromSeed(43);
  bk.onArrival(arrival(a, 0, 0), 1.0);
  bk.onArrival(arrival(a, 1, 0), 5.0);  // reset before the world was fixed
  ASSERT_EQ(bk.selectWorld(nullptr), std::optional<RobotId>(0));
  EXPECT_EQ(bk.worldSession(), std::optional<std::uint32_t>(0));
  EXPECT_EQ(bk.stats(0)->sessions.at(0).anchored_by, SessionAnchor::kWorld);
  EXPECT_EQ(bk.stats(0)->sessions.at(1).anchored_by, SessionAnchor::kNone);
  EXPECT_FALSE(bk.anchored(0));  // its current session still needs loops
}

TEST(Relocalisation, NoLoopWithinTheTimeoutReportsANewRobotUnderTheSameId) {
  TwoRobots f(30);
  f.bk.onArrival(arrival(f.b, 2, 0), 10.0);
  f.bk.onArrival(arrival(f.b, 2, 1), 20.0);
  EXPECT_TRUE(f.bk.checkRelocalisation(39.9).empty());
  const auto reported = f.bk.checkRelocalisation(40.0);
  ASSERT_EQ(reported.size(), 1u);
  EXPECT_EQ(reported[0], std::make_pair(RobotId{1}, std::uint32_t{2}));
  EXPECT_TRUE(f.bk.checkRelocalisation(100.0).empty());  // reported once
  const AgentStats* s = f.bk.stats(1);
  EXPECT_EQ(s->newRobotSessions(), 1);
  EXPECT_EQ(s->relocalisedSessions(), 0);
  EXPECT_EQ(f.bk.robots().size(), 2u);  // no duplicated robot id
  EXPECT_EQ(f.bk.robotOf(f.b), std::optional<RobotId>(1));
  // A loop that ties it later still re-localises it.
  ASSERT_TRUE(f.bk.markSessionAnchored(1, 2, SessionAnchor::kLoop, SE3::identity()));
  EXPECT_EQ(s->newRobotSessions(), 0);
  EXPECT_EQ(s->relocalisedSessions(), 1);
}

TEST(Relocalisation, StateSurvivesACheckpoint) {
  TwoRobots f(5);
  f.bk.onArrival(arrival(f.b, 2, 0), 10.0);
  f.bk.onArrival(arrival(f.a, 2, 0), 11.0);
  ASSERT_TRUE(f.bk.markSessionAnchored(1, 2, SessionAnchor::kLoop, f.T_W_A1));
  ASSERT_EQ(f.bk.checkRelocalisation(20.0).size(), 1u);  // robot 0's session 2
  server::ByteWriter w;
  f.bk.save(&w);
  Bookkeeper restored(params(5));
  server::ByteReader r(w.out.data(), w.out.size());
  ASSERT_TRUE(restored.load(&r));
  for (RobotId robot : {0u, 1u}) {
    const AgentStats* x = f.bk.stats(robot);
    const AgentStats* y = restored.stats(robot);
    ASSERT_TRUE(y);
    EXPECT_EQ(y->anchored, x->anchored) << robot;
    ASSERT_EQ(y->sessions.size(), x->sessions.size()) << robot;
    for (const auto& [id, s] : x->sessions) {
      const SessionStats& t = y->sessions.at(id);
      EXPECT_EQ(t.anchored_by, s.anchored_by) << robot << "/" << id;
      EXPECT_EQ(t.anchored_at, s.anchored_at) << robot << "/" << id;
      EXPECT_EQ(t.relocalised, s.relocalised) << robot << "/" << id;
      EXPECT_EQ(t.reported_new, s.reported_new) << robot << "/" << id;
    }
  }
  EXPECT_EQ(restored.stats(1)->relocalisedSessions(), 1);
  EXPECT_EQ(restored.stats(0)->newRobotSessions(), 1);
  EXPECT_TRUE(restored.checkRelocalisation(100.0).empty());  // not reported twice
}

TEST(Relocalisation, TimeoutIsAServerParam) {
  auto config = Config::fromString("server:\n  relocalisation_timeout_s: 12.5\n", "test");
  ASSERT_TRUE(config.ok());
  server::ServerParams p;
  ASSERT_TRUE(p.read(*config));
  EXPECT_DOUBLE_EQ(p.bookkeeper.relocalisation_timeout_s, 12.5);
  ConfigWriter out;
  p.write(out);
  EXPECT_NE(out.yaml().find("relocalisation_timeout_s: 12.5"), std::string::npos) << out.yaml();
  auto bad = Config::fromString("server:\n  relocalisation_timeout_s: -1\n", "test");
  ASSERT_TRUE(bad.ok());
  const Status s = p.read(*bad);
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().find("server.relocalisation_timeout_s"), std::string::npos) << s.error();
}
