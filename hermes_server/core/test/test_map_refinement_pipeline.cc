// Map refinement inside the server (map_manager.cc): three agents of the
// multi-agent fixture merged with server.refinement on and off; with it the
// windows run after merges that accepted loops, the cross-robot loop ties get
// more consistent, the merged trajectory stays as accurate, and the map (with
// its refined edges) survives save / load.
#include <gtest/gtest.h>

#include <cstdio>

#include "hermes/core/evaluation.h"
#include "hermes/server/map_refinement.h"
#include "hermes/server/server.h"
#include "hermes/server/server_outputs.h"
#include "support/multi_agent_fixture.h"

namespace hermes {
namespace server {
namespace {

const std::string kGt = std::string(HERMES_TRAJECTORY_DIR) + "/";

struct Outcome {
  double ate_m = 0;
  TieConsistency ties;
  RefinementDiagnostics diag;
  std::vector<std::uint8_t> map_bytes;
  std::size_t refined_edges = 0;
};

Outcome runHall(bool refine) {
  fixture::Options options;
  auto fx = fixture::makeFixture({{kGt + "MH_01_easy.txt", 0.0, 20.0, -1},
                                  {kGt + "MH_02_easy.txt", 0.0, 20.0, -1},
                                  {kGt + "MH_03_medium.txt", 0.0, 17.0, -1}},
                                 options);
  EXPECT_TRUE(fx.ok()) << (fx ? "" : fx.error());
  if (!fx) return {};
  ServerParams params;
  params.map.refinement.enabled = refine;
  auto server = Server::create(params, HERMES_SOURCE_DIR);
  EXPECT_TRUE(server.ok()) << (server ? "" : server.error());
  if (!server) return {};
  double now = 0;
  for (const auto* frame : fixture::roundRobin(*fx)) {
    now += 1.0;
    (void)(*server)->onFrame(frame->data(), frame->size(), nullptr, now);
    (void)(*server)->process(now, -1);
  }
  EXPECT_EQ((*server)->counters().merge_errors, 0u) << (*server)->counters().last_error;
  std::vector<eval::AgentTrajectories> agents;
  for (std::size_t i = 0; i < fx->agents.size(); ++i) {
    eval::AgentTrajectories a;
    a.name = "agent" + std::to_string(i);
    a.gt = fx->agents[i].gt_body;
    a.est = agentTrajectory((*server)->map(), *(*server)->bookkeeper().robotOf(fx->agents[i].uuid), fx->T_B_C);
    agents.push_back(std::move(a));
  }
  eval::EvalParams ep;
  ep.align = eval::AlignMode::kSE3;
  ep.max_dt = 0.01;
  auto ev = eval::evaluateAgents(agents, ep);
  EXPECT_TRUE(ev.ok());
  Outcome out;
  out.ate_m = ev ? ev->merged_ate.trans_m.rmse : 1.0;
  out.ties = measureLoopTies((*server)->map());
  out.diag = (*server)->mapManager().refinementDiagnostics();
  out.map_bytes = (*server)->map().toBytes();
  out.refined_edges = (*server)->map().refined_edges.size();
  return out;
}

TEST(MapRefinementPipeline, RefinesAfterLoopsKeepsAccuracyAndSaves) {
  const Outcome off = runHall(false);
  const Outcome on = runHall(true);
  std::printf("off: ATE %.2f mm, tie reprojection RMS %.3f px (%d cross ties)\n"
              "on:  ATE %.2f mm, tie reprojection RMS %.3f px (%d cross ties); %d windows, %d applied, "
              "%zu refined edges; last window %d free / %d held keyframes, %d landmarks, %d ties, %.0f ms, %s\n",
              1e3 * off.ate_m, off.ties.cross_reproj_rms_px, off.ties.cross_ties, 1e3 * on.ate_m,
              on.ties.cross_reproj_rms_px, on.ties.cross_ties, on.diag.runs, on.diag.applied, on.refined_edges,
              on.diag.last.free_keyframes, on.diag.last.fixed_keyframes, on.diag.last.landmarks,
              on.diag.last.ties, on.diag.last.time_ms, on.diag.last.termination.c_str());
  EXPECT_EQ(off.diag.runs, 0);
  EXPECT_EQ(off.refined_edges, 0u);
  EXPECT_GT(on.diag.applied, 0);
  EXPECT_GT(on.refined_edges, 0u);
  EXPECT_GT(off.ties.cross_ties, 100);
  EXPECT_LT(on.ties.cross_reproj_rms_px, off.ties.cross_reproj_rms_px);
  EXPECT_LT(on.ate_m, 1.2 * off.ate_m + 0.001);
  // The refined map saves and loads whole.
  auto loaded = GlobalMap::fromBytes(on.map_bytes, "pipeline");
  ASSERT_TRUE(loaded.ok()) << loaded.error();
  EXPECT_EQ(loaded->refined_edges.size(), on.refined_edges);
  EXPECT_NEAR(measureLoopTies(*loaded).cross_reproj_rms_px, on.ties.cross_reproj_rms_px, 1e-9);
}

}  // namespace
}  // namespace server
}  // namespace hermes
