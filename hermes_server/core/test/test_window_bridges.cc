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

const std::string kGt = std::string(HERMES_SHARED_DATA_DIR) + "/euroc_gt/";

/// Information (translation x diagonal) of every odometry edge of the graph
/// that enters `key`, after feeding `subs` of one agent to a fresh server.
double bridgeInformationInto(const std::vector<Submap>& subs, const KeyframeKey& key) {
  auto created = Server::create(ServerParams(), HERMES_SOURCE_DIR);
  EXPECT_TRUE(created.ok()) << created.error();
  Server& server = **created;
  double now = 0;
  for (const Submap& s : subs) {
    auto f = encodeSubmap(s);
    EXPECT_TRUE(f.ok()) << f.error();
    const ReceiveResult r = server.onFrame(f->data(), f->size(), nullptr, now += 1);
    EXPECT_EQ(r.verdict, ArrivalVerdict::kAccept) << r.reason;
    server.process(now, -1);
  }
  Expected<PoseGraph> g = server.mapManager().buildPoseGraph();
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

}  // namespace
}  // namespace server
}  // namespace hermes
