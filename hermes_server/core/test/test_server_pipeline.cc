// End-to-end server pipeline on a multi-agent fixture built from real EuRoC
// ground truth: frames in, merged world map out.
#include <gtest/gtest.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <set>

#include "hermes/core/evaluation.h"
#include "hermes/server/server.h"
#include "hermes/server/server_outputs.h"
#include "support/multi_agent_fixture.h"

namespace hermes {
namespace server {
namespace {

const std::string kGt = std::string(HERMES_TRAJECTORY_DIR) + "/";

fixture::Fixture makeHall() {
  std::vector<fixture::AgentSpec> specs = {
      {kGt + "MH_01_easy.txt", 0.0, 20.0, -1},
      {kGt + "MH_02_easy.txt", 0.0, 21.0, 10.0},  // resets: session 1, ids from 0
      {kGt + "MH_03_medium.txt", 0.0, 17.0, -1},
  };
  fixture::Options options;
  auto fx = fixture::makeFixture(specs, options);
  EXPECT_TRUE(fx.ok()) << (fx ? "" : fx.error());
  return fx ? std::move(*fx) : fixture::Fixture{};
}

std::unique_ptr<Server> makeServer() {
  ServerParams params;
  auto server = Server::create(params, HERMES_SOURCE_DIR);
  EXPECT_TRUE(server.ok()) << (server ? "" : server.error());
  return server ? std::move(*server) : nullptr;
}

/// Feeds the agents' frames round-robin, processing after each round.
void feed(Server* server, const fixture::Fixture& fx, bool resend) {
  std::size_t rounds = 0;
  for (const auto& a : fx.agents) rounds = std::max(rounds, a.frames.size());
  double now = 0;
  for (std::size_t r = 0; r < rounds; ++r) {
    for (const auto& a : fx.agents) {
      if (r >= a.frames.size()) continue;
      now += 1.0;
      const ReceiveResult res = server->onFrame(a.frames[r].data(), a.frames[r].size(), nullptr, now);
      EXPECT_EQ(res.verdict, ArrivalVerdict::kAccept) << res.reason;
      if (resend && r > 0) {  // an agent that missed an ack resends its previous submap
        const auto& prev = a.frames[r - 1];
        const ReceiveResult dup = server->onFrame(prev.data(), prev.size(), nullptr, now);
        EXPECT_EQ(dup.verdict, ArrivalVerdict::kDuplicate);
        EXPECT_TRUE(dup.acknowledge);
      }
    }
    server->process(now, -1);
  }
}

eval::MultiAgentEval evaluate(const Server& server, const fixture::Fixture& fx) {
  std::vector<eval::AgentTrajectories> agents;
  for (std::size_t i = 0; i < fx.agents.size(); ++i) {
    const auto robot = server.bookkeeper().robotOf(fx.agents[i].uuid);
    EXPECT_TRUE(robot.has_value());
    eval::AgentTrajectories a;
    a.name = "agent" + std::to_string(i);
    a.gt = fx.agents[i].gt_body;
    a.est = agentTrajectory(server.map(), *robot, fx.T_B_C);
    agents.push_back(std::move(a));
  }
  eval::EvalParams params;
  params.align = eval::AlignMode::kSE3;
  params.max_dt = 0.01;
  auto ev = eval::evaluateAgents(agents, params);
  EXPECT_TRUE(ev.ok()) << (ev ? "" : ev.error());
  return ev ? *ev : eval::MultiAgentEval{};
}

TEST(ServerPipeline, MergesAgentsRejectsFalseLoopsAndWritesOutputs) {
  const fixture::Fixture fx = makeHall();
  ASSERT_EQ(fx.agents.size(), 3u);
  auto server = makeServer();
  ASSERT_NE(server, nullptr);

  // Corrupt every 4th geometrically verified loop (wrong relative pose):
  // PCM must reject all of them.
  std::set<std::pair<KeyframeKey, KeyframeKey>> corrupted;
  int loops_seen = 0;
  server->mapManager().setLoopHook([&](const KeyframeKey& a, const KeyframeKey& b, SE3* T) {
    if (loops_seen++ % 4 != 3) return;
    Vec6 xi;
    xi << 0.8, -0.5, 0.3, 0.0, 0.25, 0.3;
    *T = *T * SE3::exp(xi);
    corrupted.insert({a, b});
  });

  feed(server.get(), fx, /*resend=*/true);
  EXPECT_EQ(server->pending(), 0u);
  EXPECT_EQ(server->counters().merge_errors, 0u) << server->counters().last_error;
  std::size_t submaps = 0;
  for (const auto& a : fx.agents) submaps += a.frames.size();
  EXPECT_EQ(server->counters().merged, submaps);
  EXPECT_EQ(server->receiverStats().duplicates, submaps - fx.agents.size());

  // All agents (current sessions) in one world frame.
  EXPECT_EQ(server->mapManager().agentsMerged(), 3);
  const auto* reset = server->map().trajectory(*server->bookkeeper().robotOf(fx.agents[1].uuid), 1);
  ASSERT_NE(reset, nullptr);
  EXPECT_TRUE(reset->anchored);
  EXPECT_EQ(reset->keyframes.begin()->first, 0u);

  // No corrupted loop survives PCM.
  EXPECT_GT(corrupted.size(), 2u);
  std::size_t accepted = 0;
  for (const LoopEdge& e : server->map().loops) {
    if (!e.accepted) continue;
    ++accepted;
    EXPECT_EQ(corrupted.count({e.a, e.b}), 0u) << "false loop accepted";
  }
  EXPECT_GT(accepted, 10u);
  EXPECT_EQ(server->mapManager().loopsAccepted(), accepted);

  const eval::MultiAgentEval ev = evaluate(*server, fx);
  std::printf("loops: %zu accepted, %zu rejected (%zu corrupted); merged ATE rmse %.4f m max %.4f m\n",
              server->mapManager().loopsAccepted(), server->mapManager().loopsRejected(),
              corrupted.size(), ev.merged_ate.trans_m.rmse, ev.merged_ate.trans_m.max);
  EXPECT_LT(ev.merged_ate.trans_m.rmse, 0.02);  // measured 0.0044 m

  // Outputs.
  const std::string dir = ::testing::TempDir() + "/hermes_server_pipeline";
  std::filesystem::create_directories(dir);
  auto paths = writeAgentTrajectories(server->map(), dir);
  ASSERT_TRUE(paths.ok());
  EXPECT_EQ(paths->size(), 3u);
  auto traj = readTumTrajectory(paths->front());
  ASSERT_TRUE(traj.ok());
  EXPECT_GT(traj->size(), 30u);
  std::vector<std::uint32_t> owners;
  const std::vector<Vec3> points = server->map().landmarkPositionsWorld(&owners);
  EXPECT_GT(points.size(), 1000u);
  ASSERT_EQ(owners.size(), points.size());  // every robot's landmarks, each with its robot
  EXPECT_EQ(std::set<std::uint32_t>(owners.begin(), owners.end()).size(), 3u);
  for (bool binary : {false, true}) {
    const std::string ply = dir + (binary ? "/map_bin.ply" : "/map.ply");
    ASSERT_TRUE(writePly(ply, points, binary));
    auto back = readPly(ply);
    ASSERT_TRUE(back.ok()) << back.error();
    ASSERT_EQ(back->size(), points.size());
    EXPECT_LT(((*back)[7] - points[7]).norm(), 1e-3);
  }
  const RunMetrics m = serverMetrics(*server);
  EXPECT_EQ(*m.agents_merged, 3);
  EXPECT_EQ(*m.loops_accepted, static_cast<int64_t>(accepted));
  EXPECT_TRUE(m.timings_ms.count("loop_closure"));
  EXPECT_TRUE(m.timings_ms.count("submap"));
  EXPECT_EQ(m.per_agent.size(), 3u);

  // Save / reload the global map.
  const std::string file = dir + "/global_map.hgm";
  ASSERT_TRUE(server->map().save(file));
  auto loaded = GlobalMap::load(file);
  ASSERT_TRUE(loaded.ok()) << loaded.error();
  EXPECT_EQ(loaded->keyframeCount(), server->map().keyframeCount());
  EXPECT_EQ(loaded->loops.size(), server->map().loops.size());
  const std::vector<Vec3> points2 = loaded->landmarkPositionsWorld();
  ASSERT_EQ(points2.size(), points.size());
  double worst = 0;
  for (std::size_t i = 0; i < points.size(); ++i) worst = std::max(worst, (points[i] - points2[i]).norm());
  EXPECT_LT(worst, 1e-6);
  // Corruption is detected.
  auto bytes = server->map().toBytes();
  bytes[bytes.size() / 2] ^= 0x10;
  EXPECT_FALSE(GlobalMap::fromBytes(bytes, "corrupted").ok());
  bytes.resize(10);
  EXPECT_FALSE(GlobalMap::fromBytes(bytes, "short").ok());
}

TEST(ServerPipeline, GarbageFramesAreRejectedWithoutCrashing) {
  auto server = makeServer();
  ASSERT_NE(server, nullptr);
  std::vector<std::uint8_t> junk(300, 0xab);
  const ReceiveResult r = server->onFrame(junk.data(), junk.size(), nullptr, 1.0);
  EXPECT_EQ(r.verdict, ArrivalVerdict::kRejected);
  EXPECT_FALSE(r.acknowledge);
  EXPECT_EQ(server->process(2.0, -1), 0);
  EXPECT_EQ(server->mapManager().agentsMerged(), 0);
}

TEST(ServerPipeline, ParamsReadServerKeys) {
  auto config = Config::fromString(
      "server:\n  csa: \"off\"\n  map:\n    rig_neighbours: 3\n  pcm:\n    min_clique_size: 4\n",
      "test");
  ASSERT_TRUE(config.ok());
  ServerParams p;
  ASSERT_TRUE(p.read(*config)) << p.read(*config).error();
  EXPECT_FALSE(p.credibility.enabled);
  EXPECT_EQ(p.map.rig_neighbours, 3);
  EXPECT_EQ(p.map.pcm.min_clique_size, 4);
  auto bad = Config::fromString("server:\n  map:\n    rig_neighbours: 0\n", "test");
  ASSERT_TRUE(bad.ok());
  EXPECT_FALSE(p.read(*bad));
}

TEST(ServerOutputs, RobotColoursMatchTheRvizPathsAndWrap) {
  // config/rviz/hermes.rviz colours the paths of robots 0, 1, 2 like this.
  EXPECT_EQ(robotColour(0), (std::array<std::uint8_t, 3>{31, 119, 180}));
  EXPECT_EQ(robotColour(1), (std::array<std::uint8_t, 3>{255, 127, 14}));
  EXPECT_EQ(robotColour(2), (std::array<std::uint8_t, 3>{44, 160, 44}));
  EXPECT_EQ(robotColour(12), robotColour(2));
  EXPECT_NE(robotColour(3), robotColour(2));
}

}  // namespace
}  // namespace server
}  // namespace hermes
