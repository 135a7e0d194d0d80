// Map-based loop candidates: once robots are anchored, a new keyframe is also
// tried against stored keyframes near its estimated world pose, so that a
// revisit the bag-of-words retrieval does not propose is still closed.
#include <gtest/gtest.h>

#include "hermes/server/server.h"
#include "support/multi_agent_fixture.h"

namespace hermes {
namespace server {
namespace {

struct Outcome {
  int place_accepted_late = 0, map_accepted_late = 0, map_attempts = 0, map_far = 0;
};

/// Two robots on MH_01 / MH_02 (the same hall); after `blind_after` seconds
/// the place recognition proposes nothing (as in poor light).
Outcome run(int spatial_candidates, double blind_after) {
  auto fx = fixture::hallPair(20.0, 200);
  EXPECT_TRUE(fx.ok()) << fx.error();
  ServerParams params;
  params.map.spatial_candidates = spatial_candidates;
  auto created = Server::create(params, HERMES_SOURCE_DIR);
  EXPECT_TRUE(created.ok()) << created.error();
  Server& server = **created;
  double t0 = 1e300;
  for (const auto& a : fx->agents) t0 = std::min(t0, a.submaps.front().keyframes.front().stamp);
  auto stampOf = [&](const KeyframeKey& k) {
    const StoredKeyframe* kf = server.map().keyframe(k);
    return kf ? kf->keyframe.stamp - t0 : 0.0;
  };
  server.mapManager().setCandidateHook([&](const KeyframeKey& q, std::vector<PlaceCandidate>* c) {
    if (stampOf(q) > blind_after) c->clear();
  });
  Outcome out;
  server.mapManager().setAttemptHook([&](const LoopAttempt& a) {
    if (!a.candidate) return;
    if (a.spatial) ++out.map_attempts;
    if (a.status != LoopStatus::kAccepted || stampOf(a.query) <= blind_after) return;
    ++(a.spatial ? out.map_accepted_late : out.place_accepted_late);
  });
  double now = 0;
  for (std::size_t r = 0; r < fx->agents[0].frames.size() || r < fx->agents[1].frames.size(); ++r) {
    for (const auto& agent : fx->agents) {
      if (r >= agent.frames.size()) continue;
      const ReceiveResult res = server.onFrame(agent.frames[r].data(), agent.frames[r].size(), nullptr, now += 1);
      EXPECT_EQ(res.verdict, ArrivalVerdict::kAccept) << res.reason;
    }
    server.process(now, -1);
  }
  EXPECT_EQ(server.counters().merge_errors, 0u) << server.counters().last_error;
  EXPECT_EQ(server.mapManager().agentsMerged(), 2);
  return out;
}

TEST(SpatialCandidates, CloseRevisitsThePlaceRecognitionMisses) {
  const Outcome with = run(1, 10.0);
  EXPECT_EQ(with.place_accepted_late, 0);
  EXPECT_GT(with.map_accepted_late, 5);
  const Outcome without = run(0, 10.0);
  EXPECT_EQ(without.map_attempts, 0);
  EXPECT_EQ(without.map_accepted_late, 0);
}

}  // namespace
}  // namespace server
}  // namespace hermes
