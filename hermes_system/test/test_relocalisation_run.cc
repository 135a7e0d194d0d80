// A robot that resets its map mid-run (`hermes run --agent-reset NAME@S`): its
// pipeline starts again with a fresh map and the next session, its odometry at
// identity. If it revisits the places of the global map, verified loops
// re-localise the new session: same robot id, its merged poses in the world as
// accurate as before. If it never does (here: every place candidate of the new
// session withheld by the test hook), it is reported as a new robot after
// server.relocalisation_timeout_s, and the server is fine.
#include <gtest/gtest.h>

#include <algorithm>
#include <nlohmann/json.hpp>
#include <set>

#include "hermes/system/offline_run.h"
#include "hermes/system/run_results.h"
#include "support/hall_run.h"
#include "support/rendered_hall.h"

using namespace hermes;

namespace {

const system::OfflineAgent* agentNamed(const system::OfflineRun& run, const std::string& name) {
  for (const system::OfflineAgent& a : run.agents())
    if (a.name == name) return &a;
  return nullptr;
}

const AgentMetrics* metricsOf(const RunMetrics& m, const std::string& name) {
  for (const AgentMetrics& a : m.per_agent)
    if (a.agent == name) return &a;
  return nullptr;
}

/// Every robot once in the outputs and in the bookkeeper; spools drained; no merge error.
void expectOneIdPerRobot(const system::OfflineRun& run, const RunMetrics& m) {
  std::set<std::string> names;
  for (const AgentMetrics& a : m.per_agent) EXPECT_TRUE(names.insert(a.agent).second) << a.agent << " twice";
  EXPECT_EQ(m.per_agent.size(), run.agents().size());
  EXPECT_EQ(run.server().bookkeeper().robots().size(), run.agents().size());
  std::set<RobotId> ids;
  for (const system::OfflineAgent& a : run.agents()) {
    ASSERT_TRUE(a.robot) << a.name;
    EXPECT_TRUE(ids.insert(*a.robot).second) << a.name << " shares a robot id";
    EXPECT_EQ(a.pipeline->uplink()->backlogBytes(), 0u) << a.name << ": spool not drained";
  }
  EXPECT_EQ(run.server().counters().merge_errors, 0u) << run.server().counters().last_error;
}

/// The reset robot's metrics (two sessions) and the run's totals (only it reset).
void expectSessionCounts(const RunMetrics& metrics, const std::string& name, int relocalised, int reported_new) {
  const AgentMetrics* m = metricsOf(metrics, name);
  ASSERT_TRUE(m) << name;
  EXPECT_EQ(m->sessions.value_or(0), 2);
  EXPECT_EQ(m->relocalised.value_or(-1), relocalised);
  EXPECT_EQ(m->reported_new.value_or(-1), reported_new);
  EXPECT_EQ(metrics.relocalised.value_or(-1), relocalised);
  EXPECT_EQ(metrics.robots_new.value_or(-1), reported_new);
}

/// Runs to the end, evaluates, prints the report, checks one id per robot.
system::RunResults runAndCheck(system::OfflineRun& run) {
  EXPECT_TRUE(run.run());
  system::RunResults r = system::evaluateRun(run);
  std::printf("%s", system::formatReport(run, r).c_str());
  expectOneIdPerRobot(run, r.metrics);
  return r;
}

}  // namespace

TEST(RelocalisationRun, RobotResetMidRunIsReLocalisedUnderItsId) {
  // The two robots fly the same route for 30 s; MH_02 loses its map at 15 s.
  system::SystemParams params = test_support::testRunParams();
  const std::string victim = "MH_02_easy";
  params.clock.agent_reset = {{victim, 15.0}};
  auto run = test_support::makeMeetingRun(params, "reloc_revisit");
  ASSERT_TRUE(run);
  const system::RunResults r = runAndCheck(*run);

  const system::OfflineAgent* a = agentNamed(*run, victim);
  ASSERT_TRUE(a && a->robot);
  ASSERT_EQ(a->resets.size(), 1u);
  const system::AgentResetRecord& reset = a->resets[0];
  EXPECT_NEAR(reset.at_s, 15.0, 0.011);
  EXPECT_EQ(reset.new_session, reset.old_session + 1);
  EXPECT_GT(reset.frame, 100u);  // it went on from the frame due at 15 s
  EXPECT_EQ(a->pipeline->session(), reset.new_session);
  std::printf("reset: frame %zu, session %u -> %u, %zu old-session submaps carried in the spool\n",
              reset.frame, reset.old_session, reset.new_session, reset.spool_carried);

  const server::Server& srv = run->server();
  const AgentStats* st = srv.bookkeeper().stats(*a->robot);
  ASSERT_EQ(st->sessions.size(), 2u);
  const SessionStats& fresh = st->sessions.at(reset.new_session);
  EXPECT_EQ(fresh.anchored_by, SessionAnchor::kLoop);
  EXPECT_TRUE(fresh.relocalised);
  EXPECT_FALSE(fresh.reported_new);
  EXPECT_NE(st->sessions.at(reset.old_session).anchored_by, SessionAnchor::kNone);
  std::printf("world robot %u, %s's robot %u; new session anchored %.2f s after its first submap\n",
              srv.bookkeeper().worldAgent().value_or(99), victim.c_str(), *a->robot,
              fresh.anchored_at - fresh.first_time);
  // Its new odometry started at identity mid-route: the loops put it where it
  // is, not at the origin of the world.
  const server::TrajectoryMap* t = srv.map().trajectory(*a->robot, reset.new_session);
  ASSERT_TRUE(t && t->anchored);
  EXPECT_GT(t->T_W_A.translation().norm(), 0.3) << "the new session sits at the world origin";

  expectSessionCounts(r.metrics, victim, /*relocalised=*/1, /*reported_new=*/0);
  const AgentMetrics* m = metricsOf(r.metrics, victim);
  ASSERT_TRUE(m);
  EXPECT_EQ(r.metrics.agents_merged.value_or(0), 2);
  // Both sessions' merged poses, against the one ground truth of the robot.
  ASSERT_TRUE(m->merged_ate_rmse_m && r.metrics.ate_rmse_m);
  std::printf("merged ATE: %s %.2f cm, all %.2f cm\n", victim.c_str(), *m->merged_ate_rmse_m * 100,
              *r.metrics.ate_rmse_m * 100);
  EXPECT_LT(*m->merged_ate_rmse_m, 0.08);
  EXPECT_LT(*r.metrics.ate_rmse_m, 0.08);
  ASSERT_TRUE(m->matched_poses);
  const std::uint64_t old_keyframes = st->sessions.at(reset.old_session).keyframes;
  EXPECT_GT(static_cast<std::uint64_t>(*m->matched_poses), old_keyframes + fresh.keyframes / 2)
      << "both sessions in the robot's merged trajectory";
  const nlohmann::json j = system::resultsJson(r);
  EXPECT_EQ(j["relocalised"].get<int>(), 1);
}

TEST(RelocalisationRun, RobotResetThatNeverRevisitsIsReportedNewAfterTheTimeout) {
  system::SystemParams params = test_support::testRunParams();
  params.run.agent.setWindowPeriod(2.5);  // windows of the new session before the end
  params.server.bookkeeper.relocalisation_timeout_s = 1.5;
  const std::string victim = test_support::hallSequences().back();
  params.clock.agent_reset = {{victim, 4.0}};
  auto run = test_support::makeHallRun(params, "reloc_never");
  ASSERT_TRUE(run);
  // It never comes back to a mapped place: no place candidate to or from its new session.
  run->onServerCreated([](server::Server& s) {
    s.mapManager().setCandidateHook([](const KeyframeKey& q, std::vector<PlaceCandidate>* c) {
      if (q.session > 0) return c->clear();
      c->erase(std::remove_if(c->begin(), c->end(),
                              [](const PlaceCandidate& p) { return p.key.session > 0; }),
               c->end());
    });
  });
  const system::RunResults r = runAndCheck(*run);

  const system::OfflineAgent* a = agentNamed(*run, victim);
  ASSERT_TRUE(a && a->robot);
  ASSERT_EQ(a->resets.size(), 1u);
  const AgentStats* st = run->server().bookkeeper().stats(*a->robot);
  ASSERT_EQ(st->sessions.size(), 2u) << "the old session sent nothing before the reset";
  const SessionStats& fresh = st->sessions.at(a->resets[0].new_session);
  EXPECT_EQ(fresh.anchored_by, SessionAnchor::kNone);
  EXPECT_TRUE(fresh.reported_new);
  EXPECT_FALSE(run->server().bookkeeper().anchored(*a->robot));
  expectSessionCounts(r.metrics, victim, /*relocalised=*/0, /*reported_new=*/1);
  // The other robots merged as usual.
  EXPECT_GE(r.metrics.agents_merged.value_or(0), 2);
  const nlohmann::json j = system::resultsJson(r);
  EXPECT_EQ(j["robots_new"].get<int>(), 1);
}

TEST(RelocalisationRun, BadResetsAreRefusedByName) {
  auto parsed = system::parseAgentResets("a@1.5, b@ 20");
  ASSERT_TRUE(parsed);
  ASSERT_EQ(parsed->size(), 2u);
  EXPECT_EQ((*parsed)[1], (system::AgentReset{"b", 20.0}));
  EXPECT_EQ(system::parseAgentResets(system::formatAgentResets(*parsed)).value(), *parsed);
  for (const std::string bad : {"a", "a@", "@3", "a@-1", "a@x", "a@1,", "a@nan"}) {
    auto p = system::parseAgentResets(bad);
    EXPECT_FALSE(p) << bad;
    if (!p) {
      EXPECT_NE(p.error().find("NAME@S"), std::string::npos) << p.error();
    }
  }
  auto config = Config::fromString("system:\n  agent_reset: \"MH_01@oops\"\n", "test");
  ASSERT_TRUE(config.ok());
  system::ClockParams c;
  const Status s = c.read(*config);
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().find("system.agent_reset"), std::string::npos) << s.error();
  EXPECT_NE(s.error().find("MH_01@oops"), std::string::npos) << s.error();
  // A name no agent has, and a time after the agent's last frame.
  system::SystemParams params = test_support::testRunParams();
  for (const system::AgentReset& bad : {system::AgentReset{"nobody", 2.0},
                                        system::AgentReset{test_support::hallSequences()[0], 99.0}}) {
    params.clock.agent_reset = {bad};
    const std::string dir = test_support::renderedHall();
    std::vector<system::AgentSource> sources;
    for (const std::string& name : test_support::hallSequences()) {
      auto ds = Dataset::open(dir + "/" + name, params.run.dataset);
      ASSERT_TRUE(ds.ok()) << ds.error();
      sources.push_back({name, std::move(*ds), 0});
    }
    auto run = system::OfflineRun::create(params, std::move(sources),
                                          ::testing::TempDir() + "/hermes_reloc_bad/spool", HERMES_SOURCE_DIR);
    ASSERT_FALSE(run.ok()) << bad.agent;
    EXPECT_NE(run.error().find("system.agent_reset '" + bad.agent), std::string::npos) << run.error();
  }
}
