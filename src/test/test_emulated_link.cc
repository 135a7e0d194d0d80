#include <gtest/gtest.h>

#include "hermes/core/emulated_link.h"

using namespace hermes;

namespace {
LinkMessage msg(int sender, std::uint64_t id, std::size_t bytes) {
  LinkMessage m;
  m.sender = sender;
  m.id = id;
  m.bytes = bytes;
  return m;
}
}  // namespace

TEST(LinkTrace, ParsesAndRejectsWithLineNumbers) {
  auto t = LinkTrace::fromString(
      "time_s,rate_mbitps,latency_ms,loss\n0,30,5,0\n10,0,5,0\n40,20,5,0.2\n", "trace.csv");
  ASSERT_TRUE(t.ok()) << t.error();
  EXPECT_DOUBLE_EQ(t->at(5).rate_mbitps, 30);
  EXPECT_DOUBLE_EQ(t->at(10).rate_mbitps, 0);
  EXPECT_DOUBLE_EQ(t->at(100).loss, 0.2);
  EXPECT_DOUBLE_EQ(t->nextChange(10), 40);
  auto bad = LinkTrace::fromString("time_s,rate_mbitps,latency_ms,loss\n0,30,5,0\n5,x,1,0\n", "b.csv");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().find("b.csv:3"), std::string::npos) << bad.error();
  EXPECT_FALSE(LinkTrace::fromString("time,rate\n0,1\n", "h.csv").ok());
  EXPECT_FALSE(LinkTrace::fromString("time_s,rate_mbitps,latency_ms,loss\n0,1,0,1.5\n", "l.csv").ok());
  EXPECT_FALSE(LinkTrace::fromString("time_s,rate_mbitps,latency_ms,loss\n5,1,0,0\n2,1,0,0\n", "o.csv").ok());
  EXPECT_FALSE(LinkTrace::fromCsv("/no/such/trace.csv").ok());
}

TEST(SharedLink, RateAndLatency) {
  SharedLink link(LinkTrace::constant(8.0, 20.0), 1, 1);
  link.send(msg(0, 1, 1000000), 0.0);  // 1 MB at 8 Mbit/s = 1 s
  EXPECT_TRUE(link.advanceTo(1.0).empty());
  auto d = link.advanceTo(1.05);
  ASSERT_EQ(d.size(), 1u);
  EXPECT_NEAR(d[0].arrival_time, 1.0 + 0.020, 1e-6);
  EXPECT_FALSE(d[0].lost);
}

TEST(SharedLink, FairShareBetweenSenders) {
  SharedLink link(LinkTrace::constant(8.0), 2, 1);
  link.send(msg(0, 1, 1000000), 0.0);
  link.send(msg(1, 1, 1000000), 0.0);
  link.advanceTo(1.0);
  // After 1 s each sender got about half of 1 MB through.
  EXPECT_NEAR(static_cast<double>(link.queuedBytes(0)), 500000.0, 3000.0);
  EXPECT_NEAR(static_cast<double>(link.queuedBytes(1)), 500000.0, 3000.0);
  auto d = link.advanceTo(3.0);
  ASSERT_EQ(d.size(), 2u);
  EXPECT_NEAR(d[1].arrival_time, 2.0, 1e-3);
}

TEST(SharedLink, OutageStopsTraffic) {
  auto trace = LinkTrace::fromString("time_s,rate_mbitps,latency_ms,loss\n0,8,0,0\n0.5,0,0,0\n30.5,8,0,0\n", "t");
  ASSERT_TRUE(trace.ok());
  SharedLink link(*trace, 1, 1);
  link.send(msg(0, 1, 1000000), 0.0);
  EXPECT_TRUE(link.advanceTo(30.0).empty());
  EXPECT_NEAR(static_cast<double>(link.queuedBytes(0)), 500000.0, 2000.0);
  EXPECT_LT(link.ackArrival(10.0), 0.0);  // acks cannot cross an outage
  auto d = link.advanceTo(31.1);
  ASSERT_EQ(d.size(), 1u);
  EXPECT_NEAR(d[0].arrival_time, 31.0, 1e-3);
}

TEST(SharedLink, LossFractionAndDeterminism) {
  auto run = [](std::uint64_t seed) {
    SharedLink link(LinkTrace::constant(100.0, 0.0, 0.2), 1, seed);
    for (int i = 0; i < 2000; ++i) link.send(msg(0, i, 1000), i * 0.001);
    std::vector<bool> lost;
    for (const auto& d : link.advanceTo(10.0)) lost.push_back(d.lost);
    return lost;
  };
  const auto a = run(7), b = run(7), c = run(8);
  ASSERT_EQ(a.size(), 2000u);
  EXPECT_EQ(a, b);
  EXPECT_NE(a, c);
  const double frac = std::count(a.begin(), a.end(), true) / 2000.0;
  EXPECT_NEAR(frac, 0.2, 0.03);
}
