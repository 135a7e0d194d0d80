// Issue 20, "Done when": three honest robots (EuRoC ground-truth fixture,
// authenticated) with forged, unknown-robot, replayed and flooding traffic
// beside them. Every bad frame is rejected with its reason and counted; the
// honest robots' results (every frame accepted once, submaps applied, keyframe
// poses in the world, accepted loops, ATE) are identical to a run without the
// attackers.
#include <gtest/gtest.h>

#include <map>
#include <set>
#include <tuple>

#include "hermes/core/crc32.h"
#include "hermes/core/evaluation.h"
#include "hermes/core/frame_auth.h"
#include "hermes/server/server.h"
#include "hermes/server/server_outputs.h"
#include "support/multi_agent_fixture.h"

namespace hermes {
namespace server {
namespace {

using Frame = std::vector<std::uint8_t>;
const std::string kGt = std::string(HERMES_TRAJECTORY_DIR) + "/";
constexpr int kFloodPerRound = 12;
constexpr int kFloodFromRound = 2;

FrameKey keyOf(std::uint8_t seed) {
  FrameKey k;
  for (std::size_t i = 0; i < k.bytes.size(); ++i) k.bytes[i] = static_cast<std::uint8_t>(seed * 37 + 5 * i);
  return k;
}

Frame sign(const Frame& f, const FrameKey& key) {
  auto t = signFrame(f, key);
  EXPECT_TRUE(t.ok()) << t.error();
  return t.ok() ? *t : Frame{};
}

void resealCrc(Frame* f) {
  const std::uint32_t crc = crc32(f->data() + kWireCrcOffset + 4, f->size() - kWireCrcOffset - 4,
                                  crc32(f->data(), kWireCrcOffset));
  for (int i = 0; i < 4; ++i) (*f)[kWireCrcOffset + i] = static_cast<std::uint8_t>(crc >> (8 * i));
}

/// A valid submap that touches nothing of the others: keyframes without
/// keypoints (no words, no landmarks, no loops). The flooder sends these.
Frame floodFrame(const Uuid& agent, std::uint64_t seq, const PinholeIntrinsics& camera,
                 const FrameKey& key) {
  Submap s;
  s.header.agent = agent;
  s.header.seq = seq;
  s.header.t_start = static_cast<double>(seq);
  s.header.t_end = s.header.t_start + 1;
  s.cameras = {camera};
  Keyframe kf;
  kf.id = seq;
  kf.stamp = s.header.t_start;
  s.keyframes = {kf};
  auto f = encodeSubmap(s);
  EXPECT_TRUE(f.ok()) << f.error();
  return sign(*f, key);
}

struct Attackers {
  Uuid flooder = uuidFromSeed(900), stranger = uuidFromSeed(901);
  FrameKey flooder_key = keyOf(90), stranger_key = keyOf(91);
  std::uint64_t flood_seq = 0;
};

/// What an honest robot ends up with, in terms that do not depend on robot ids.
struct HonestResult {
  std::vector<ReceiveCode> codes;  ///< of its own frames, in sending order
  std::uint64_t applied = 0, keyframes = 0, landmarks = 0;
  std::map<std::pair<std::uint32_t, KeyframeId>, Mat4> T_W_C;  ///< (session, id) -> pose
  std::set<std::uint32_t> anchored_sessions;
};

struct RunResult {
  std::vector<HonestResult> honest;
  std::set<std::tuple<int, std::uint32_t, KeyframeId, int, std::uint32_t, KeyframeId>> loops;
  double merged_ate = -1;
  ReceiverStats stats;
  RunMetrics metrics;
  std::size_t flooder_peak_held = 0;
};

RunResult run(const fixture::Fixture& fx, const std::vector<FrameKey>& keys, Attackers* attack) {
  Keyring ring;
  for (std::size_t i = 0; i < fx.agents.size(); ++i)
    ring.add(fx.agents[i].uuid, "honest" + std::to_string(i), keys[i]);
  if (attack) ring.add(attack->flooder, "flooder", attack->flooder_key);
  ServerParams params;
  params.auth.enabled = true;
  params.queue.max_per_robot = 4;
  auto created = Server::create(params, HERMES_SOURCE_DIR, ring);
  EXPECT_TRUE(created.ok()) << (created ? "" : created.error());
  if (!created) return {};
  Server& server = **created;

  RunResult out;
  out.honest.resize(fx.agents.size());
  std::vector<Frame> sent_last(fx.agents.size());
  std::size_t rounds = 0;
  for (const auto& a : fx.agents) rounds = std::max(rounds, a.frames.size());
  double now = 0;
  auto expect = [&](const Frame& f, ReceiveCode code, bool ack, const char* what) {
    const ReceiveResult r = server.onFrame(f.data(), f.size(), nullptr, now);
    EXPECT_EQ(r.code, code) << what << ": " << r.reason;
    EXPECT_EQ(r.acknowledge, ack) << what;
    EXPECT_FALSE(r.reason.empty()) << what;
  };
  for (std::size_t round = 0; round < rounds; ++round) {
    for (std::size_t i = 0; i < fx.agents.size(); ++i) {
      const auto& agent = fx.agents[i];
      if (round >= agent.frames.size()) continue;
      now += 1.0;
      const Frame honest = sign(agent.frames[round], keys[i]);
      if (attack) {
        // Forged: the honest frame's (uuid, session, seq), body altered, CRC
        // fixed, sent FIRST -- had it got in, the honest frame would be a duplicate.
        Frame forged = honest;
        forged[kWireFixedBytes + forged.size() / 3] ^= 0x20;
        resealCrc(&forged);
        expect(forged, ReceiveCode::kBadTag, false, "forged body");
        expect(agent.frames[round], ReceiveCode::kMissingTag, false, "untagged");
        expect(sign(agent.frames[round], attack->flooder_key), ReceiveCode::kBadTag, false,
               "another robot's key");
        // Unknown robot: a real submap under a uuid the server has no key for.
        Submap stolen = agent.submaps[round];
        stolen.header.agent = attack->stranger;
        expect(sign(*encodeSubmap(stolen), attack->stranger_key), ReceiveCode::kUnknownRobot,
               false, "unknown robot");
      }
      const ReceiveResult r = server.onFrame(honest.data(), honest.size(), nullptr, now);
      out.honest[i].codes.push_back(r.code);
      if (attack && round > 0)  // replay of the robot's previous (applied) frame
        expect(sent_last[i], ReceiveCode::kReplay, true, "replay");
      sent_last[i] = honest;
    }
    if (attack && round >= kFloodFromRound) {
      EXPECT_TRUE(server.bookkeeper().worldAgent().has_value())
          << "the flood starts after the world frame is fixed";
      for (int k = 0; k < kFloodPerRound; ++k) {
        const Frame f = floodFrame(attack->flooder, attack->flood_seq++, fx.camera,
                                   attack->flooder_key);
        const ReceiveResult r = server.onFrame(f.data(), f.size(), nullptr, now);
        EXPECT_TRUE(r.code == ReceiveCode::kAccepted || r.code == ReceiveCode::kQuota) << r.reason;
        if (r.code == ReceiveCode::kQuota) {
          EXPECT_FALSE(r.acknowledge);
        }
        const Frame again = floodFrame(attack->flooder, 0, fx.camera, attack->flooder_key);
        server.onFrame(again.data(), again.size(), nullptr, now);  // a robot looping on a resend
      }
      const auto flooder = server.bookkeeper().robotOf(attack->flooder);
      if (flooder && server.heldLoad(*flooder))
        out.flooder_peak_held = std::max(out.flooder_peak_held, server.heldLoad(*flooder)->submaps);
    }
    server.process(now, -1);
  }

  for (std::size_t i = 0; i < fx.agents.size(); ++i) {
    const RobotId robot = *server.bookkeeper().robotOf(fx.agents[i].uuid);
    HonestResult& h = out.honest[i];
    const AgentStats* st = server.bookkeeper().stats(robot);
    h.applied = st->submaps_applied;
    h.keyframes = st->keyframes;
    h.landmarks = st->landmarks;
    for (std::uint32_t session = 0; session < 4; ++session) {
      const TrajectoryMap* t = server.map().trajectory(robot, session);
      if (!t) continue;
      if (t->anchored) h.anchored_sessions.insert(session);
      for (const auto& [id, kf] : t->keyframes) h.T_W_C[{session, id}] = kf.T_W_C.matrix();
    }
  }
  std::map<RobotId, int> honest_index;
  for (std::size_t i = 0; i < fx.agents.size(); ++i)
    honest_index[*server.bookkeeper().robotOf(fx.agents[i].uuid)] = static_cast<int>(i);
  for (const LoopEdge& e : server.map().loops) {
    if (!e.accepted) continue;
    const int a = honest_index.count(e.a.agent) ? honest_index[e.a.agent] : -1;
    const int b = honest_index.count(e.b.agent) ? honest_index[e.b.agent] : -1;
    out.loops.insert({a, e.a.session, e.a.id, b, e.b.session, e.b.id});
  }
  std::vector<eval::AgentTrajectories> trajectories;
  for (std::size_t i = 0; i < fx.agents.size(); ++i) {
    eval::AgentTrajectories a;
    a.name = "honest" + std::to_string(i);
    a.gt = fx.agents[i].gt_body;
    a.est = agentTrajectory(server.map(), *server.bookkeeper().robotOf(fx.agents[i].uuid), fx.T_B_C);
    trajectories.push_back(std::move(a));
  }
  eval::EvalParams ep;
  ep.align = eval::AlignMode::kSE3;
  ep.max_dt = 0.01;
  if (auto ev = eval::evaluateAgents(trajectories, ep)) out.merged_ate = ev->merged_ate.trans_m.rmse;
  out.stats = server.receiverStats();
  out.metrics = serverMetrics(server);
  return out;
}

TEST(HostileTraffic, AttackersAreRejectedWithReasonsHonestResultsUnchanged) {
  std::vector<fixture::AgentSpec> specs = {
      {kGt + "MH_01_easy.txt", 0.0, 20.0, -1},
      {kGt + "MH_02_easy.txt", 0.0, 21.0, 10.0},  // a session reset on the way
      {kGt + "MH_03_medium.txt", 0.0, 17.0, -1},
  };
  auto fx = fixture::makeFixture(specs, fixture::Options{});
  ASSERT_TRUE(fx.ok()) << fx.error();
  const std::vector<FrameKey> keys = {keyOf(1), keyOf(2), keyOf(3)};

  const RunResult calm = run(*fx, keys, nullptr);
  Attackers attackers;
  const RunResult hostile = run(*fx, keys, &attackers);

  // Every bad frame rejected, with its reason counted.
  std::size_t honest_frames = 0;
  for (const auto& a : fx->agents) honest_frames += a.frames.size();
  const std::size_t replays = honest_frames - fx->agents.size();
  const ReceiverStats& s = hostile.stats;
  EXPECT_EQ(s.count(ReceiveCode::kBadTag), 2 * honest_frames);
  EXPECT_EQ(s.count(ReceiveCode::kMissingTag), honest_frames);
  EXPECT_EQ(s.count(ReceiveCode::kUnknownRobot), honest_frames);
  const std::size_t flooded = attackers.flood_seq;
  EXPECT_EQ(s.count(ReceiveCode::kReplay), replays + flooded);  // + the flooder looping on its seq 0
  EXPECT_GT(s.count(ReceiveCode::kQuota), flooded / 2);
  EXPECT_EQ(s.count(ReceiveCode::kAccepted) + s.count(ReceiveCode::kQuota),
            honest_frames + flooded);
  EXPECT_EQ(s.count(ReceiveCode::kMalformed), 0u);  // nothing forged reached the decoder
  EXPECT_LE(hostile.flooder_peak_held, 4u);         // server.queue.max_per_robot
  EXPECT_EQ(hostile.metrics.frames_refused.at("bad_tag"), static_cast<int64_t>(2 * honest_frames));
  EXPECT_EQ(hostile.metrics.frames_refused.at("unknown_robot"), static_cast<int64_t>(honest_frames));
  EXPECT_EQ(hostile.metrics.frames_refused.at("quota"),
            static_cast<int64_t>(s.count(ReceiveCode::kQuota)));
  EXPECT_TRUE(calm.metrics.frames_refused.empty());
  std::printf("hostile run: %zu honest frames, %zu flood frames (%zu refused for quota), "
              "refused: bad_tag %zu missing_tag %zu unknown_robot %zu replay %zu\n",
              honest_frames, flooded, s.count(ReceiveCode::kQuota), s.count(ReceiveCode::kBadTag),
              s.count(ReceiveCode::kMissingTag), s.count(ReceiveCode::kUnknownRobot),
              s.count(ReceiveCode::kReplay));

  // The honest robots' results are those of the calm run.
  ASSERT_EQ(calm.honest.size(), 3u);
  ASSERT_EQ(hostile.honest.size(), 3u);
  for (std::size_t i = 0; i < 3; ++i) {
    const HonestResult& c = calm.honest[i];
    const HonestResult& h = hostile.honest[i];
    EXPECT_EQ(h.codes, c.codes) << "robot " << i;
    for (ReceiveCode code : h.codes) EXPECT_EQ(code, ReceiveCode::kAccepted);
    EXPECT_EQ(h.applied, fx->agents[i].frames.size());
    EXPECT_EQ(h.applied, c.applied);
    EXPECT_EQ(h.keyframes, c.keyframes);
    EXPECT_EQ(h.landmarks, c.landmarks);
    EXPECT_EQ(h.anchored_sessions, c.anchored_sessions);
    EXPECT_FALSE(h.anchored_sessions.empty());
    ASSERT_EQ(h.T_W_C.size(), c.T_W_C.size());
    double worst = 0;
    for (const auto& [key, T] : c.T_W_C) worst = std::max(worst, (h.T_W_C.at(key) - T).cwiseAbs().maxCoeff());
    EXPECT_EQ(worst, 0.0) << "robot " << i << ": keyframe poses differ by up to " << worst;
  }
  EXPECT_EQ(hostile.loops, calm.loops);
  EXPECT_GT(calm.loops.size(), 10u);
  EXPECT_EQ(hostile.merged_ate, calm.merged_ate);
  EXPECT_GT(calm.merged_ate, 0.0);
  EXPECT_LT(calm.merged_ate, 0.02);
  std::printf("merged ATE %.5f m (calm) vs %.5f m (hostile); %zu accepted loops both\n",
              calm.merged_ate, hostile.merged_ate, calm.loops.size());
}

}  // namespace
}  // namespace server
}  // namespace hermes
