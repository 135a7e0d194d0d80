// Loop closure side by side (server.map.loop_threads): the candidates of one
// merge are verified on several threads and taken in the order chosen, so one
// thread and two find the same loops, with the same ids, in the same order.
#include <gtest/gtest.h>

#include <sstream>

#include "hermes/server/server.h"
#include "support/multi_agent_fixture.h"

namespace hermes {
namespace server {
namespace {

struct Trace {
  std::vector<std::string> attempts;  ///< every attempt: query, candidate, status, inliers
  std::vector<LoopEdge> loops;
  std::size_t accepted = 0;
  int merged = 0;
};

std::string describe(const KeyframeKey& k) {
  return std::to_string(k.agent) + "/" + std::to_string(k.session) + "/" + std::to_string(k.id);
}

Trace run(const fixture::Fixture& fx, int threads) {
  ServerParams params;
  params.map.loop_threads = threads;
  auto created = Server::create(params, HERMES_SOURCE_DIR);
  EXPECT_TRUE(created.ok()) << created.error();
  Server& server = **created;
  Trace trace;
  server.mapManager().setAttemptHook([&](const LoopAttempt& a) {
    std::ostringstream s;
    s << describe(a.query) << " -> " << (a.candidate ? describe(a.candidate->key) : "none") << " "
      << a.spatial << " " << toString(a.status) << " " << a.matches << " " << a.inliers << " "
      << a.ransac_iterations << " " << a.reason;  // the give-up and pre-check (defaults on) too
    trace.attempts.push_back(s.str());
  });
  double now = 0;
  for (std::size_t r = 0; r < fx.agents[0].frames.size() || r < fx.agents[1].frames.size(); ++r) {
    for (const auto& agent : fx.agents) {
      if (r >= agent.frames.size()) continue;
      EXPECT_EQ(server.onFrame(agent.frames[r].data(), agent.frames[r].size(), nullptr, now += 1).verdict,
                ArrivalVerdict::kAccept);
    }
    server.process(now, -1);
  }
  EXPECT_EQ(server.counters().merge_errors, 0u) << server.counters().last_error;
  trace.loops = server.map().loops;
  trace.accepted = server.mapManager().loopsAccepted();
  trace.merged = server.mapManager().agentsMerged();
  return trace;
}

TEST(LoopThreads, OneAndTwoThreadsFindTheSameLoopsInTheSameOrder) {
  auto fx = fixture::hallPair(15.0, 200);
  ASSERT_TRUE(fx.ok()) << fx.error();
  const Trace one = run(*fx, 1), two = run(*fx, 2);
  ASSERT_GT(one.loops.size(), 5u);  // there is something to compare
  EXPECT_EQ(one.merged, 2);
  EXPECT_EQ(one.attempts, two.attempts);
  ASSERT_EQ(one.loops.size(), two.loops.size());
  for (std::size_t i = 0; i < one.loops.size(); ++i) {
    const LoopEdge &a = one.loops[i], &b = two.loops[i];
    EXPECT_EQ(a.id, b.id);
    EXPECT_EQ(a.a, b.a);
    EXPECT_EQ(a.b, b.b);
    EXPECT_EQ(a.inliers, b.inliers);
    EXPECT_EQ(a.accepted, b.accepted);
    EXPECT_TRUE(a.T_a_b.matrix() == b.T_a_b.matrix()) << "loop " << i;  // bit for bit
  }
  EXPECT_EQ(one.accepted, two.accepted);
}

TEST(LoopThreads, ThreadCountIsValidated) {
  MapManagerParams p;
  p.loop_threads = 0;
  EXPECT_FALSE(p.validate().ok());
  p.loop_threads = 4;
  EXPECT_TRUE(p.validate().ok());
}

}  // namespace
}  // namespace server
}  // namespace hermes
