// A server started on a prior map (server.prior_map, server.h): mission 1's
// robots MH_01 and MH_02 (two sessions) map the hall (fixture::hallTrio) and
// the server's state is saved as a checkpoint; mission 2's server starts on it. Its robots - MH_03, new, and
// MH_01 again under the same name - register as new robots, are placed in
// mission 1's world frame by loops against the prior map, and the prior's
// keyframes stay. An unreadable prior map is an error naming the file (or,
// optional, a problem and an empty start); nothing in its folder is changed.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "hermes/core/crc32.h"
#include "hermes/server/server.h"
#include "support/multi_agent_fixture.h"

namespace hermes {
namespace server {
namespace {

namespace fs = std::filesystem;

const fixture::Fixture& hall() { return fixture::hallTrio(); }

std::string freshDir(const std::string& tag) {
  const std::string dir = ::testing::TempDir() + "/hermes_prior_" + tag;
  fs::remove_all(dir);
  return dir;
}

/// Feeds the agents' frames round robin from time `t0`, merging after each round.
void feed(Server* s, const std::vector<std::size_t>& agents, double t0) {
  std::size_t rounds = 0;
  for (std::size_t a : agents) rounds = std::max(rounds, hall().agents[a].frames.size());
  double now = t0;
  for (std::size_t r = 0; r < rounds; ++r) {
    for (std::size_t a : agents) {
      if (r >= hall().agents[a].frames.size()) continue;
      const std::vector<std::uint8_t>& f = hall().agents[a].frames[r];
      const ReceiveResult res = s->onFrame(f.data(), f.size(), nullptr, now += 1.0);
      EXPECT_TRUE(res.acknowledge) << res.reason;
      EXPECT_EQ(res.verdict, ArrivalVerdict::kAccept) << "agent " << a << " round " << r;
    }
    s->process(now);
  }
  s->process(now + 1e3);
}

/// Mission 1 (MH_01, MH_02) checkpointed into `dir`; returns its keyframe count.
std::size_t missionOne(const std::string& dir) {
  ServerParams params;
  params.checkpoint.dir = dir;
  auto server = Server::create(params, HERMES_SOURCE_DIR);
  EXPECT_TRUE(server.ok()) << (server ? "" : server.error());
  if (!server) return 0;
  feed(server->get(), {0, 1}, 0.0);
  EXPECT_EQ((*server)->mapManager().agentsMerged(), 2);
  EXPECT_TRUE((*server)->checkpoint(1e4));
  return (*server)->map().keyframeCount();
}

Expected<std::unique_ptr<Server>> onPrior(const std::string& prior, bool optional = false) {
  ServerParams params;
  params.checkpoint.prior_map = prior;
  params.checkpoint.prior_map_optional = optional;
  return Server::create(params, HERMES_SOURCE_DIR);
}

std::vector<std::uint8_t> readBytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::vector<std::uint8_t>((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
}

void writeBytes(const std::string& path, const std::vector<std::uint8_t>& b) {
  std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(b.data()), b.size());
}

}  // namespace

TEST(PriorMap, NewRobotsAndAReturningOneArePlacedInThePriorsWorldFrame) {
  const std::string dir = freshDir("mission1");
  const std::size_t prior_keyframes = missionOne(dir);
  ASSERT_GT(prior_keyframes, 0u);
  const std::vector<std::string> before = CheckpointStore::listCheckpoints(dir);
  ASSERT_FALSE(before.empty());

  auto server = onPrior(dir);
  ASSERT_TRUE(server.ok()) << server.error();
  Server& s = **server;
  EXPECT_EQ(s.resumeReport().prior_map, before.front());
  EXPECT_TRUE(s.resumeReport().problems.empty()) << s.resumeReport().problems.front();
  EXPECT_EQ(s.mapManager().priorAgents(), 2);
  EXPECT_EQ(s.mapManager().agentsMerged(), 0) << "the prior's robots are not this mission's";
  EXPECT_EQ(s.map().keyframeCount(), prior_keyframes);
  EXPECT_EQ(s.counters().merged, 0u);
  const std::optional<RobotId> world = s.bookkeeper().worldAgent();
  ASSERT_TRUE(world.has_value());
  EXPECT_TRUE(s.bookkeeper().isPrior(*world));
  EXPECT_EQ(s.bookkeeper().stats(*world)->name.rfind(kPriorPrefix, 0), 0u) << s.bookkeeper().stats(*world)->name;

  // Mission 2: MH_03 (new) and MH_01 again, same uuid: both accepted, not duplicates.
  feed(&s, {2, 0}, 0.0);
  EXPECT_EQ(s.counters().merge_errors, 0u) << s.counters().last_error;
  EXPECT_EQ(s.bookkeeper().worldAgent(), world) << "no new world frame";
  for (std::size_t a : {std::size_t(2), std::size_t(0)}) {
    const std::optional<RobotId> robot = s.bookkeeper().robotOf(hall().agents[a].uuid);
    ASSERT_TRUE(robot.has_value()) << a;
    EXPECT_FALSE(s.bookkeeper().isPrior(*robot)) << a;
    EXPECT_TRUE(s.bookkeeper().anchored(*robot)) << "agent " << a << " not placed in the prior's frame";
    // Placed on this mission's clock (its first submaps), not at the prior's last arrival.
    const SessionStats& first = s.bookkeeper().stats(*robot)->sessions.begin()->second;
    EXPECT_GE(first.anchored_at, first.first_time) << a;
    EXPECT_LE(first.anchored_at - first.first_time, 4.0) << "agent " << a << " placed " << first.anchored_at
                                                         << " s, first submap " << first.first_time << " s";
  }
  EXPECT_EQ(s.mapManager().agentsMerged(), 2);
  EXPECT_EQ(s.mapManager().priorAgents(), 2);
  EXPECT_GT(s.map().keyframeCount(), prior_keyframes);
  // The returning MH_01 sits where the prior's MH_01 (renamed, sealAsPrior) put the same keyframes.
  const Uuid prior_mh01 = agentUuid("prior:" + hermes::toString(hall().agents[0].uuid));
  double worst = 0;
  std::size_t compared = 0;
  for (const auto& [tid, t] : s.map().trajectories) {
    if (t.uuid != hall().agents[0].uuid) continue;
    for (const auto& [tid2, t2] : s.map().trajectories) {
      if (t2.uuid != prior_mh01) continue;
      for (const auto& [id, kf] : t.keyframes) {
        auto it = t2.keyframes.find(id);
        if (it == t2.keyframes.end()) continue;
        worst = std::max(worst, (kf.T_W_C.translation() - it->second.T_W_C.translation()).norm());
        ++compared;
      }
    }
  }
  EXPECT_GT(compared, 0u);
  EXPECT_LT(worst, 0.10) << "MH_01 of mission 2 is placed away from mission 1's";
  // Nothing in the prior's folder changed.
  EXPECT_EQ(CheckpointStore::listCheckpoints(dir), before);
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file()) EXPECT_EQ(e.path().extension(), ".hck") << e.path();
}

TEST(PriorMap, AnUnreadablePriorIsAnErrorOrWithOptionalAnEmptyStart) {
  const std::string dir = freshDir("damaged");
  ASSERT_GT(missionOne(dir), 0u);
  for (const std::string& f : CheckpointStore::listCheckpoints(dir)) {  // every one damaged
    std::vector<std::uint8_t> bytes = readBytes(f);
    bytes[bytes.size() / 2] ^= 0x10;
    writeBytes(f, bytes);
  }
  auto refused = onPrior(dir);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().find("prior map '" + dir + "'"), std::string::npos) << refused.error();
  EXPECT_NE(refused.error().find("checksum mismatch"), std::string::npos) << refused.error();
  EXPECT_NE(refused.error().find("prior_map_optional"), std::string::npos) << refused.error();

  auto empty = onPrior(dir, /*optional=*/true);
  ASSERT_TRUE(empty.ok()) << empty.error();
  EXPECT_TRUE((*empty)->resumeReport().prior_map.empty());
  ASSERT_EQ((*empty)->resumeReport().problems.size(), 1u);
  EXPECT_NE((*empty)->resumeReport().problems[0].find("empty map"), std::string::npos);
  EXPECT_EQ((*empty)->map().keyframeCount(), 0u);
  EXPECT_FALSE((*empty)->bookkeeper().worldAgent().has_value());
  for (const auto& e : fs::recursive_directory_iterator(dir))
    EXPECT_NE(e.path().extension(), ".refused") << "a prior's files are never renamed";

  auto missing = onPrior(dir + "_nowhere");
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.error().find("holds no server checkpoint"), std::string::npos) << missing.error();
}

TEST(PriorMap, AnotherVersionIsRefusedByName) {
  const std::string dir = freshDir("version");
  ASSERT_GT(missionOne(dir), 0u);
  for (const std::string& f : CheckpointStore::listCheckpoints(dir)) {
    std::vector<std::uint8_t> b = readBytes(f);
    const std::uint32_t v = kCheckpointVersion + 1;
    std::memcpy(b.data() + 4, &v, 4);
    const std::uint32_t c = crc32(b.data(), b.size() - 4);
    std::memcpy(b.data() + b.size() - 4, &c, 4);
    writeBytes(f, b);
  }
  auto refused = onPrior(dir);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().find("format version " + std::to_string(kCheckpointVersion + 1) +
                                 ", this build reads version " + std::to_string(kCheckpointVersion)),
            std::string::npos)
      << refused.error();
}

TEST(PriorMap, ThePriorCannotBeTheServersOwnCheckpointFolder) {
  ServerParams params;
  params.checkpoint.dir = freshDir("same");
  params.checkpoint.prior_map = params.checkpoint.dir + "/.";
  const Status s = params.validate();
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().find("own checkpoint_dir"), std::string::npos) << s.error();
}

}  // namespace server
}  // namespace hermes
