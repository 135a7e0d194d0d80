// Keyframe extensions (map_types.h): a later submap adds keypoints to keyframes
// an earlier one carried; the server appends them and closes the loops whose
// rigs hold those keyframes again.
#include <gtest/gtest.h>

#include <algorithm>

#include "hermes/core/evaluation.h"
#include "hermes/core/wire_format.h"
#include "hermes/server/server.h"
#include "hermes/server/server_outputs.h"
#include "support/multi_agent_fixture.h"

namespace hermes {
namespace server {
namespace {

/// The keypoints from index `from` on, as extensions of `s`'s keyframes.
std::vector<Keyframe> tailAsExtensions(const Submap& s, std::size_t from) {
  std::vector<Keyframe> out;
  for (const Keyframe& kf : s.keyframes) {
    if (kf.keypoints.size() <= from) continue;
    Keyframe e = kf;
    e.keypoints.assign(kf.keypoints.begin() + static_cast<std::ptrdiff_t>(from), kf.keypoints.end());
    e.descriptors.assign(kf.descriptors.begin() + static_cast<std::ptrdiff_t>(from), kf.descriptors.end());
    e.keypoint_landmark.assign(e.keypoints.size(), kInvalidId);
    out.push_back(std::move(e));
  }
  return out;
}

/// `s` with only the keypoints before index `to` (observations of the others dropped).
Submap head(Submap s, std::size_t to) {
  for (Keyframe& kf : s.keyframes) {
    const std::size_t n = std::min(to, kf.keypoints.size());
    kf.keypoints.resize(n);
    kf.descriptors.resize(n);
    kf.keypoint_landmark.resize(n);
  }
  std::vector<Landmark> kept;
  for (Landmark& lm : s.landmarks) {
    std::vector<Observation> obs;
    for (const Observation& o : lm.observations)
      if (o.keypoint < to) obs.push_back(o);
    if (obs.empty()) continue;
    lm.observations = std::move(obs);
    kept.push_back(std::move(lm));
  }
  s.landmarks = std::move(kept);
  return s;
}

class KeyframeExtensions : public ::testing::TestWithParam<int> {};

// Parameter: server.map.closure_budget. Under a budget the merge does not
// measure the loops again itself: they wait with the deferred closures and are
// measured while no submap waits (process() after the queue drained).
TEST_P(KeyframeExtensions, AppendKeypointsToStoredKeyframesAndReverifyTheirLoops) {
  auto fx = fixture::hallPair(16.0, 240);
  ASSERT_TRUE(fx.ok()) << fx.error();
  ServerParams params;
  params.map.closure_budget = GetParam();
  params.map.closure_budget_swarm = 0;  // 0 = the merge measures them again itself
  auto created = Server::create(params, HERMES_SOURCE_DIR);
  ASSERT_TRUE(created.ok()) << created.error();
  Server& server = **created;

  // Each agent's first submap goes out with half its keypoints; the second
  // brings the rest as extensions (and one of a keyframe never sent).
  const std::size_t half = 120;
  std::vector<std::vector<std::vector<std::uint8_t>>> frames(fx->agents.size());
  for (std::size_t a = 0; a < fx->agents.size(); ++a) {
    const std::vector<Submap>& subs = fx->agents[a].submaps;
    ASSERT_GE(subs.size(), 3u);
    Submap second = subs[1];
    std::vector<Keyframe> ext = tailAsExtensions(subs[0], half);
    Keyframe unknown = ext.front();
    unknown.id = 999999;
    ext.insert(ext.begin(), unknown);
    second.keyframes.insert(second.keyframes.begin(), ext.begin(), ext.end());
    ASSERT_EQ(second.validate(), "");
    std::vector<Submap> sent = {head(subs[0], half), second};
    sent.insert(sent.end(), subs.begin() + 2, subs.end());
    for (const Submap& s : sent) {
      auto f = encodeSubmap(s);
      ASSERT_TRUE(f.ok()) << f.error();
      frames[a].push_back(std::move(*f));
    }
  }
  double now = 0;
  for (std::size_t r = 0; r < frames[0].size() || r < frames[1].size(); ++r) {
    for (const auto& agent : frames) {
      if (r >= agent.size()) continue;
      const ReceiveResult res = server.onFrame(agent[r].data(), agent[r].size(), nullptr, now += 1);
      EXPECT_EQ(res.verdict, ArrivalVerdict::kAccept) << res.reason;
    }
    server.process(now, -1);
  }
  for (int idle = 0; idle < 1000 && server.deferredClosures() > 0; ++idle) server.process(now += 1, -1);
  EXPECT_EQ(server.deferredClosures(), 0u);
  EXPECT_EQ(server.counters().merge_errors, 0u) << server.counters().last_error;
  if (GetParam() > 0) EXPECT_EQ(server.counters().loops_reverify_deferred, server.counters().loops_reverified);
  else EXPECT_EQ(server.counters().loops_reverify_deferred, 0u);
  EXPECT_EQ(server.counters().extensions_unknown, 2u);
  EXPECT_EQ(server.counters().keyframes_extended,
            fx->agents[0].submaps[0].keyframes.size() + fx->agents[1].submaps[0].keyframes.size());
  EXPECT_GT(server.counters().loops_reverified, 0u);

  // The stored keyframes hold every keypoint again, in the original order;
  // the extensions added no keyframe.
  for (std::size_t a = 0; a < fx->agents.size(); ++a) {
    const auto robot = server.bookkeeper().robotOf(fx->agents[a].uuid);
    ASSERT_TRUE(robot.has_value());
    std::size_t sent_keyframes = 0;
    for (const Submap& s : fx->agents[a].submaps) sent_keyframes += s.keyframes.size();
    const TrajectoryMap* t = server.map().trajectory(*robot, fx->agents[a].submaps[0].header.session);
    ASSERT_NE(t, nullptr);
    EXPECT_EQ(t->keyframes.size(), sent_keyframes);
    for (const Keyframe& original : fx->agents[a].submaps[0].keyframes) {
      const StoredKeyframe* k = server.map().keyframe({*robot, t->session, original.id});
      ASSERT_NE(k, nullptr);
      ASSERT_EQ(k->keyframe.keypoints.size(), original.keypoints.size());
      EXPECT_EQ(k->keyframe.descriptors, original.descriptors);
      for (std::size_t p = half; p < original.keypoints.size(); ++p)
        EXPECT_EQ(k->keyframe.keypoint_landmark[p], kInvalidId);
    }
  }
  EXPECT_EQ(server.mapManager().agentsMerged(), 2);
  std::vector<eval::AgentTrajectories> agents;
  for (std::size_t a = 0; a < fx->agents.size(); ++a) {
    const auto robot = server.bookkeeper().robotOf(fx->agents[a].uuid);
    agents.push_back({"agent" + std::to_string(a), fx->agents[a].gt_body,
                      agentTrajectory(server.map(), *robot, fx->T_B_C)});
  }
  eval::EvalParams ep;
  ep.align = eval::AlignMode::kSE3;
  ep.max_dt = 0.01;
  auto ev = eval::evaluateAgents(agents, ep);
  ASSERT_TRUE(ev.ok()) << ev.error();
  EXPECT_LT(ev->merged_ate.trans_m.rmse, 0.02);
}

INSTANTIATE_TEST_SUITE_P(ClosureBudget, KeyframeExtensions, ::testing::Values(0, 4),
                         [](const ::testing::TestParamInfo<int>& i) {
                           return i.param == 0 ? std::string("NoBudget") : "Budget" + std::to_string(i.param);
                         });

}  // namespace
}  // namespace server
}  // namespace hermes
