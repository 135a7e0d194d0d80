// Sparse-pair gate (server.map.sparse_pair_loops / sparse_pair_sigma_m): a
// closure between two trajectories that few accepted loops tie yet is accepted
// up to the looser translation sigma; once the pair has that many loops the
// closure's own gate (loop_closure.max_translation_sigma_m) applies again.
#include <gtest/gtest.h>

#include <iostream>

#include "hermes/server/server.h"
#include "support/multi_agent_fixture.h"

namespace hermes {
namespace server {
namespace {

constexpr double kTightGate = 0.002;  // [m] most right closures of the clip fail it

struct Outcome {
  std::size_t accepted = 0;
  int degenerate = 0;  ///< closures refused as poorly constrained
  int merged = 0;
};

Outcome run(const fixture::Fixture& fx, int sparse_pair_loops) {
  ServerParams params;
  params.map.loop_closure.max_translation_sigma_m = kTightGate;
  params.map.sparse_pair_loops = sparse_pair_loops;
  params.map.sparse_pair_sigma_m = 0.05;
  auto created = Server::create(params, HERMES_SOURCE_DIR);
  EXPECT_TRUE(created.ok()) << created.error();
  Server& server = **created;
  Outcome o;
  server.mapManager().setAttemptHook([&](const LoopAttempt& a) {
    if (a.candidate && a.status == LoopStatus::kDegenerate) ++o.degenerate;
  });
  double now = 0;
  for (const std::vector<std::uint8_t>* frame : fixture::roundRobin(fx)) {
    EXPECT_EQ(server.onFrame(frame->data(), frame->size(), nullptr, now += 1).verdict, ArrivalVerdict::kAccept);
    server.process(now, 1);
  }
  EXPECT_EQ(server.counters().merge_errors, 0u) << server.counters().last_error;
  o.accepted = server.mapManager().loopsAccepted();
  o.merged = server.mapManager().agentsMerged();
  return o;
}

TEST(SparsePairGate, LooseLoopsOnlyWhileThePairIsSparselyTied) {
  auto fx = fixture::hallPair(15.0, 200);
  ASSERT_TRUE(fx.ok()) << fx.error();
  const Outcome off = run(*fx, 0);        // the tight gate everywhere
  const Outcome few = run(*fx, 3);        // loose for a pair's first 3 loops
  const Outcome always = run(*fx, 1000);  // loose everywhere
  std::cout << "loops accepted / closures refused as poorly constrained: tight gate " << off.accepted << " / "
            << off.degenerate << ", loose for 3 loops a pair " << few.accepted << " / " << few.degenerate
            << ", always loose " << always.accepted << " / " << always.degenerate << "\n";
  EXPECT_GT(off.degenerate, 0);
  EXPECT_GT(always.accepted, off.accepted);
  EXPECT_LT(always.degenerate, off.degenerate);
  // Between the two: loose ties first, then the tight gate again.
  EXPECT_GT(few.accepted, off.accepted);
  EXPECT_LT(few.accepted, always.accepted);
  EXPECT_GE(few.merged, off.merged);
}

TEST(SparsePairGate, ParamsAreValidated) {
  MapManagerParams p;
  p.sparse_pair_loops = -1;
  EXPECT_FALSE(p.validate().ok());
  p.sparse_pair_loops = 0;
  EXPECT_TRUE(p.validate().ok());
  p.sparse_pair_sigma_m = 0;
  EXPECT_FALSE(p.validate().ok());
}

}  // namespace
}  // namespace server
}  // namespace hermes
