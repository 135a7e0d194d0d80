// Relay robots in the whole system (scenario runs, relay_network.h): on the
// rendered hall, MH_02 never reaches the server and hands its submaps to MH_01
// over an intermittent link, while MH_01's own 4G-like link has an outage.
// With relaying all three maps merge, every submap is applied exactly once
// and MH_02 gets at least relay.min_mbitps of MH_01's uplink while relayed
// (MH_01's own map weighs 0.9 of the shares);
// without it MH_02 stays out of the map.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "hermes/system/offline_run.h"
#include "hermes/system/run_results.h"
#include "support/hall_run.h"

using namespace hermes;

namespace {

std::string writeScenario() {
  const std::string dir = ::testing::TempDir() + "/hermes_relay_run";
  std::filesystem::create_directories(dir);
  std::ofstream(dir + "/mh01_4g.csv") << "time_s,rate_mbitps,latency_ms,loss\n"
                                         "0,3,40,0\n3,0,40,0\n5,3,40,0\n";
  std::ofstream(dir + "/mh02_to_mh01.csv") << "time_s,rate_mbitps,latency_ms,loss\n"
                                              "0,20,5,0\n2,0,5,0\n4,20,5,0.05\n";
  std::ofstream(dir + "/scenario.txt") << "# MH_02 reaches only MH_01\n"
                                          "link MH_01_easy server mh01_4g.csv\n"
                                          "link MH_03_medium server const:6:40\n"
                                          "link MH_02_easy MH_01_easy mh02_to_mh01.csv\n";
  return dir + "/scenario.txt";
}

std::unique_ptr<system::OfflineRun> runScenario(bool relay, system::RunResults* out) {
  system::SystemParams p;
  // MH_01's own map weighs most on its 3 Mbit/s link: MH_02 lives on its floor
  // (1.11 Mbit/s at the lowest; 0.79 with relay.min_mbitps 0).
  p.relay.own_min_share = 0.9;
  p.run.agent.uplink.buffer.fsync = false;
  p.run.agent.uplink.buffer.resend_timeout_s = 3.0;
  p.link.scenario = writeScenario();
  p.relay.enabled = relay;
  auto run = test_support::makeHallRun(p, relay ? "relay_on" : "relay_off");
  if (!run) return nullptr;
  EXPECT_TRUE(run->run());
  *out = system::evaluateRun(*run);
  std::printf("%s", system::formatReport(*run, *out).c_str());
  return run;
}

}  // namespace

TEST(RelayRun, RelayedRobotMergesExactlyOnceWithItsFloor) {
  system::RunResults r;
  auto run = runScenario(true, &r);
  ASSERT_TRUE(run);
  ASSERT_TRUE(r.relay.has_value());
  EXPECT_EQ(r.metrics.agents_merged.value_or(0), 3);
  EXPECT_TRUE(r.relay->exactly_once);
  for (const system::RelayRobotReport& rr : r.relay->robots) {
    EXPECT_TRUE(rr.exactly_once) << rr.agent << " submitted " << rr.submitted << " accepted "
                                 << rr.accepted << " applied " << rr.applied;
    EXPECT_GT(rr.own_kBps, 0.0) << rr.agent;
  }
  const system::RelayRobotReport& mh02 = r.relay->robots[1];
  ASSERT_EQ(mh02.agent, "MH_02_easy");
  EXPECT_EQ(mh02.relayed_submaps, mh02.submitted);
  EXPECT_EQ(mh02.relayed_by, "MH_01_easy");
  EXPECT_GT(r.relay->robots[0].relayed_kBps, 0.0);
  ASSERT_TRUE(r.relay->min_relayed_mbitps.has_value()) << "MH_02 never waited at its relay";
  EXPECT_GE(*r.relay->min_relayed_mbitps, 0.99 * run->params().relay.min_mbitps);
  EXPECT_EQ(run->server().counters().merge_errors, 0u);
}

TEST(RelayRun, WithoutRelayingTheUnreachableRobotStaysOut) {
  system::RunResults r;
  auto run = runScenario(false, &r);
  ASSERT_TRUE(run);
  ASSERT_TRUE(r.relay.has_value());
  EXPECT_EQ(r.metrics.agents_merged.value_or(0), 2);
  const system::RelayRobotReport& mh02 = r.relay->robots[1];
  EXPECT_EQ(mh02.applied, 0u);
  EXPECT_EQ(mh02.relayed_submaps, 0u);
  EXPECT_FALSE(r.relay->min_relayed_mbitps.has_value());
  EXPECT_TRUE(r.relay->robots[0].exactly_once);
  EXPECT_TRUE(r.relay->robots[2].exactly_once);
}
