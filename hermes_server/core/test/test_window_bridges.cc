// Bridges between an agent's windows: the server joins the last keyframe of one
// window to the first of the next with the odometry noise model; a loss of
// tracking right before that first keyframe (Keyframe::lost_before, carried on
// the wire) weakens the bridge as the agent weakens edges inside a window.
#include <gtest/gtest.h>

#include "hermes/core/odometry_noise.h"
#include "hermes/core/wire_format.h"
#include "hermes/server/server.h"
#include "support/multi_agent_fixture.h"

namespace hermes {
namespace server {
namespace {

const std::string kGt = std::string(HERMES_TRAJECTORY_DIR) + "/";

/// A fresh server that has merged `subs` of one agent (null on failure).
std::unique_ptr<Server> serverWith(const std::vector<Submap>& subs) {
  auto created = Server::create(ServerParams(), HERMES_SOURCE_DIR);
  EXPECT_TRUE(created.ok()) << created.error();
  if (!created) return nullptr;
  double now = 0;
  for (const Submap& s : subs) {
    auto f = encodeSubmap(s);
    EXPECT_TRUE(f.ok()) << f.error();
    const ReceiveResult r = (*created)->onFrame(f->data(), f->size(), nullptr, now += 1);
    EXPECT_EQ(r.verdict, ArrivalVerdict::kAccept) << r.reason;
    (*created)->process(now, -1);
  }
  return std::move(*created);
}

/// Information (translation x diagonal) of every odometry edge of the graph
/// that enters `key`, after feeding `subs` of one agent to a fresh server.
double bridgeInformationInto(const std::vector<Submap>& subs, const KeyframeKey& key) {
  std::unique_ptr<Server> server = serverWith(subs);
  if (!server) return 0;
  Expected<PoseGraph> g = server->mapManager().buildPoseGraph();
  EXPECT_TRUE(g.ok()) << g.error();
  if (!g) return 0;
  for (const auto& e : g->measurements())
    if (!e.loop && e.b.id == key.id) return e.information(0, 0);
  ADD_FAILURE() << "no odometry edge into keyframe " << key.id;
  return 0;
}

TEST(WindowBridges, ALossBeforeAWindowWeakensItsBridge) {
  fixture::Options options;
  options.keypoints = 120;
  auto fx = fixture::makeFixture({{kGt + "MH_01_easy.txt", 0.0, 12.0, -1}}, options);
  ASSERT_TRUE(fx.ok()) << fx.error();
  std::vector<Submap> subs = fx->agents[0].submaps;
  ASSERT_GE(subs.size(), 2u);
  ASSERT_FALSE(subs[1].keyframes.empty());
  const KeyframeKey first{0, subs[1].header.session, subs[1].keyframes.front().id};
  const double sound = bridgeInformationInto(subs, first);
  subs[1].keyframes.front().lost_before = true;
  const double lost = bridgeInformationInto(subs, first);
  ASSERT_GT(lost, 0.0);
  EXPECT_NEAR(sound / lost, OdometryNoiseParams().lost_inflation, 1e-6 * sound / lost);
}

TEST(WindowBridges, LoopRigsDoNotReachAcrossALossOfTracking) {
  fixture::Options options;
  options.keypoints = 120;
  auto fx = fixture::makeFixture({{kGt + "MH_01_easy.txt", 0.0, 12.0, -1}}, options);
  ASSERT_TRUE(fx.ok()) << fx.error();
  std::vector<Submap> subs = fx->agents[0].submaps;
  ASSERT_GE(subs.size(), 1u);
  ASSERT_GE(subs[0].keyframes.size(), 6u);
  const std::uint32_t session = subs[0].header.session;
  const KeyframeId lost_at = subs[0].keyframes[2].id;  // tracking lost between keyframes 1 and 2
  subs[0].keyframes[2].lost_before = true;
  std::unique_ptr<Server> server = serverWith(subs);
  ASSERT_TRUE(server);
  auto rig = [&](std::size_t index) {
    std::vector<PinholeIntrinsics> cams;
    std::vector<KeyframeId> ids;
    for (const Keyframe* k : server->mapManager().neighbours({0, session, subs[0].keyframes[index].id}, &cams))
      ids.push_back(k->id);
    EXPECT_EQ(cams.size(), ids.size() + 1);
    return ids;
  };
  // Rigs take their earlier neighbours first, then later ones.
  for (KeyframeId id : rig(1)) EXPECT_LT(id, lost_at) << "keyframe 1's rig reaches forward across the loss";
  for (std::size_t i : {2, 3})
    for (KeyframeId id : rig(i)) EXPECT_GE(id, lost_at) << "keyframe " << i << "'s rig reaches back across the loss";
  EXPECT_EQ(rig(1).size(), 1u);
  EXPECT_EQ(rig(3).size(), 2u);
  EXPECT_EQ(rig(5).size(), static_cast<std::size_t>(ServerParams().map.rig_neighbours));
}

}  // namespace
}  // namespace server
}  // namespace hermes
