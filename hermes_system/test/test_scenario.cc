// Scenario files (scenario.h): who reaches whom over time, and clear errors
// naming the file and line on bad input.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "hermes/system/scenario.h"

using namespace hermes;
using namespace hermes::system;

namespace {

const std::vector<std::string> kRobots = {"ground_1", "ground_2", "aerial_1"};

std::string dir() {
  const std::string d = ::testing::TempDir() + "/hermes_scenario_test";
  std::filesystem::create_directories(d + "/traces");
  std::ofstream(d + "/traces/g1.csv") << "time_s,rate_mbitps,latency_ms,loss\n0,8,40,0\n10,0,40,0\n14,8,40,0\n";
  return d;
}

/// The error of parsing `text` (fails the test when it parses).
std::string errorOf(const std::string& text) {
  auto sc = Scenario::parse(text, "s.txt", dir(), kRobots);
  EXPECT_FALSE(sc.ok()) << text;
  return sc.ok() ? "" : sc.error();
}

}  // namespace

TEST(Scenario, ParsesLinksTracesAndRoutesQueries) {
  const std::string text =
      "# two ground robots on 4G, one aerial robot that reaches ground_1\n"
      "link ground_1 server traces/g1.csv\n"
      "link ground_2 server const:6:30:0.01   # constant 6 Mbit/s\n"
      "\n"
      "link aerial_1 ground_1 const:20\n";
  auto sc = Scenario::parse(text, "s.txt", dir(), kRobots);
  ASSERT_TRUE(sc.ok()) << sc.error();
  ASSERT_EQ(sc->links.size(), 3u);
  const ScenarioLink* g1 = sc->serverLink("ground_1");
  ASSERT_NE(g1, nullptr);
  EXPECT_EQ(g1->line, 2);
  EXPECT_DOUBLE_EQ(g1->trace.at(12).rate_mbitps, 0.0);  // the 4G outage
  EXPECT_DOUBLE_EQ(g1->trace.at(15).rate_mbitps, 8.0);
  const ScenarioLink* g2 = sc->serverLink("ground_2");
  ASSERT_NE(g2, nullptr);
  EXPECT_DOUBLE_EQ(g2->trace.at(0).latency_ms, 30.0);
  EXPECT_DOUBLE_EQ(g2->trace.at(0).loss, 0.01);
  EXPECT_EQ(sc->serverLink("aerial_1"), nullptr);
  ASSERT_EQ(sc->robotLinks("aerial_1").size(), 1u);
  EXPECT_EQ(sc->robotLinks("aerial_1")[0]->to, "ground_1");
  // From a file: relative traces from the file's folder.
  const std::string path = dir() + "/scenario.txt";
  std::ofstream(path) << text;
  auto from_file = Scenario::fromFile(path, kRobots);
  ASSERT_TRUE(from_file.ok()) << from_file.error();
  EXPECT_EQ(from_file->origin, path);
}

TEST(Scenario, BadInputNamesFileAndLine) {
  const std::string ok2 = "link ground_2 server const:5\nlink aerial_1 ground_1 const:5\n";
  auto has = [](const std::string& err, const std::string& what) {
    EXPECT_NE(err.find(what), std::string::npos) << "'" << what << "' not in: " << err;
  };
  std::string e = errorOf("link ground_1 server const:5\nlink drone_9 ground_1 const:5\n" + ok2);
  has(e, "s.txt:2:");
  has(e, "unknown robot 'drone_9'");
  has(e, "ground_1, ground_2, aerial_1");
  e = errorOf("link ground_1 server const:5\nlink ground_1 moon const:5\n" + ok2);
  has(e, "s.txt:2:");
  has(e, "'moon'");
  has(errorOf("connect ground_1 server const:5\n" + ok2), "s.txt:1: expected 'link FROM TO TRACE'");
  has(errorOf("link ground_1 server\n" + ok2), "s.txt:1: expected");
  has(errorOf("link ground_1 ground_1 const:5\n" + ok2), "s.txt:1: a link from ground_1 to itself");
  e = errorOf("link ground_1 server const:5\n" + ok2 + "link ground_1 server const:3\n");
  has(e, "s.txt:4: a second link from ground_1 to server (first on line 1)");
  has(errorOf("link ground_1 server const:fast\n" + ok2), "s.txt:1: 'const:fast': 'fast' is not a number");
  has(errorOf("link ground_1 server const:0\n" + ok2), "s.txt:1: 'const:0': the rate must be > 0");
  has(errorOf("link ground_1 server const:5:20:1.5\n" + ok2), "loss must be in [0, 1)");
  e = errorOf("link ground_1 server traces/missing.csv\n" + ok2);
  has(e, "s.txt:1: trace of ground_1 -> server");
  has(e, "missing.csv");
  std::ofstream(dir() + "/traces/bad.csv") << "time_s,rate_mbitps,latency_ms,loss\n0,8,40,0\n5,x,40,0\n";
  e = errorOf("link ground_1 server traces/bad.csv\n" + ok2);
  has(e, "s.txt:1:");
  has(e, "bad.csv:3: expected 4 numbers");
  // Every robot needs a link; a relay needs its own server link.
  has(errorOf("link ground_1 server const:5\nlink ground_2 server const:5\n"),
      "s.txt: robot aerial_1 has no link");
  has(errorOf("link ground_1 server const:5\nlink aerial_1 ground_2 const:5\nlink ground_2 aerial_1 const:5\n"),
      "s.txt:2: ground_2 relays for aerial_1 but has no link to the server");
  auto missing = Scenario::fromFile(dir() + "/nope.txt", kRobots);
  ASSERT_FALSE(missing.ok());
  has(missing.error(), "nope.txt' cannot be opened");
}
