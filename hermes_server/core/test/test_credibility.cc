#include <gtest/gtest.h>

#include "hermes/server/credibility.h"

using namespace hermes;

namespace {

AgentEvidence evidence(double success, double bw, double opl, bool loops = false) {
  AgentEvidence e;
  e.success_rate = success;
  e.bytes_per_s = bw;
  e.obs_per_landmark = opl;
  e.has_loops = loops;
  return e;
}

PendingSubmap item(RobotId agent, std::uint64_t seq, double arrival) {
  PendingSubmap p;
  p.agent = agent;
  p.seq = seq;
  p.arrival = arrival;
  p.handle = agent * 1000 + seq;
  return p;
}

}  // namespace

TEST(Credibility, ScoresFollowTheDefinition) {
  CredibilityParams p;
  p.w_ts = 0.6;
  p.w_mc = 0.4;
  CredibilityAssessor csa(p);
  csa.setEvidence(0, evidence(1.0, 2000, 2.0));
  csa.setEvidence(1, evidence(0.5, 1000, 4.0));
  csa.setEvidence(2, evidence(0.8, 500, 1.0, /*loops=*/true));
  auto s = csa.scores();
  EXPECT_NEAR(s[0].ts, 1.0, 1e-12);
  EXPECT_NEAR(s[0].mc, 0.5, 1e-12);
  EXPECT_NEAR(s[0].c, 0.6 * 1.0 + 0.4 * 0.5, 1e-12);
  EXPECT_NEAR(s[1].ts, 0.5 * 0.5, 1e-12);
  EXPECT_NEAR(s[1].mc, 1.0, 1e-12);
  EXPECT_NEAR(s[2].ts, 0.8 * 0.25, 1e-12);
  EXPECT_NEAR(s[2].mc, 1.0, 1e-12);  // loops -> full connectivity
  EXPECT_EQ(csa.score(9).c, 0.0);    // unknown agent
  // NaN / negative evidence is cleaned, never propagates.
  csa.setEvidence(3, evidence(std::nan(""), -5, 1.0));
  EXPECT_TRUE(std::isfinite(csa.score(3).c));
  EXPECT_EQ(csa.score(3).ts, 0.0);
}

TEST(Credibility, EvidenceFromBookkeeperStats) {
  Bookkeeper bk;
  const Uuid a = uuidFromSeed(1), b = uuidFromSeed(2);
  auto arrive = [&](const Uuid& u, std::uint64_t seq, double t, std::size_t bytes, std::size_t obs) {
    SubmapArrival s;
    s.header.agent = u;
    s.header.seq = seq;
    s.bytes = bytes;
    s.keyframes = 5;
    s.landmarks = 100;
    s.observations = obs;
    bk.onArrival(s, t);
  };
  arrive(a, 0, 0, 1000, 400);
  arrive(a, 1, 5, 1000, 400);
  arrive(b, 0, 0, 1000, 200);
  arrive(b, 3, 5, 1000, 200);  // seqs 1, 2 lost
  CredibilityAssessor csa;
  csa.updateFrom(bk, [](RobotId) { return false; });
  auto s = csa.scores();
  EXPECT_NEAR(s[0].ts, 1.0, 1e-12);
  EXPECT_NEAR(s[1].ts, 0.5, 1e-12);  // success 2/4, same bandwidth
  EXPECT_NEAR(s[0].mc, 1.0, 1e-12);
  EXPECT_NEAR(s[1].mc, 0.5, 1e-12);
  EXPECT_GT(s[0].c, s[1].c);
}

TEST(Credibility, QueueServesDescendingCredibility) {
  CredibilityParams p;
  p.aging_per_s = 0.0;
  CredibilityAssessor csa(p);
  csa.setEvidence(0, evidence(0.2, 100, 1.0));
  csa.setEvidence(1, evidence(1.0, 1000, 3.0));
  csa.setEvidence(2, evidence(0.6, 600, 2.0));
  // Interleaved arrivals: 0, 1, 2, 0, 1, 2.
  for (std::uint64_t s = 0; s < 2; ++s)
    for (RobotId a = 0; a < 3; ++a) csa.push(item(a, s, static_cast<double>(s * 3 + a)));
  std::vector<std::pair<RobotId, std::uint64_t>> order;
  std::vector<PopRecord> logged;
  csa.setLogger([&](const PopRecord& r) { logged.push_back(r); });
  while (auto r = csa.pop(10.0)) order.emplace_back(r->item.agent, r->item.seq);
  const std::vector<std::pair<RobotId, std::uint64_t>> expected = {
      {1, 0}, {1, 1}, {2, 0}, {2, 1}, {0, 0}, {0, 1}};
  EXPECT_EQ(order, expected);
  ASSERT_EQ(logged.size(), 6u);
  EXPECT_EQ(csa.history().size(), 6u);
  EXPECT_EQ(logged[0].order, 0u);
  EXPECT_EQ(logged[0].queue_size, 6u);
  EXPECT_GT(logged[0].score.c, logged[2].score.c);
  EXPECT_GT(logged[2].score.c, logged[4].score.c);
  EXPECT_DOUBLE_EQ(logged[5].waited_s, 10.0 - 3.0);
  EXPECT_TRUE(csa.empty());
}

TEST(Credibility, AgingBoundsTheWaitOfALowCredibilitySubmap) {
  // Agent 1 (c = 1) sends one submap per second and the server merges one per
  // second; agent 0 (c = 0) sent one submap at t = 0. Bound: it outranks every
  // submap that arrives more than (w_TS + w_MC) / aging = 1 / 0.05 = 20 s after it.
  CredibilityParams p;
  p.aging_per_s = 0.05;
  CredibilityAssessor csa(p);
  csa.setEvidence(0, evidence(0.0, 0, 0.0));
  csa.setEvidence(1, evidence(1.0, 1000, 3.0));
  EXPECT_NEAR(csa.score(1).c, 1.0, 1e-12);
  EXPECT_NEAR(p.agingWindowS(), 20.0, 1e-12);
  csa.push(item(0, 0, 0.0));
  double served_at = -1;
  for (int t = 0; t < 100 && served_at < 0; ++t) {
    csa.push(item(1, static_cast<std::uint64_t>(t), t));
    auto r = csa.pop(t + 0.5);
    ASSERT_TRUE(r.has_value());
    if (r->item.agent == 0) served_at = r->popped_at;
  }
  ASSERT_GE(served_at, 0.0) << "low-credibility submap starved";
  EXPECT_LE(served_at, p.agingWindowS() + 1.0);
  EXPECT_GE(served_at, p.agingWindowS() - 1.0);  // and credibility did matter before that

  // Without aging the same stream starves it for the whole run.
  p.aging_per_s = 0.0;
  CredibilityAssessor no_aging(p);
  no_aging.setEvidence(0, evidence(0.0, 0, 0.0));
  no_aging.setEvidence(1, evidence(1.0, 1000, 3.0));
  no_aging.push(item(0, 0, 0.0));
  for (int t = 0; t < 100; ++t) {
    no_aging.push(item(1, static_cast<std::uint64_t>(t), t));
    EXPECT_EQ(no_aging.pop(t + 0.5)->item.agent, 1u);
  }
}

TEST(Credibility, CsaOffIsFifo) {
  auto cfg = Config::fromString("server:\n  csa: \"off\"\n  credibility:\n    w_ts: 0.7\n", "s.yaml");
  ASSERT_TRUE(cfg.ok());
  CredibilityParams p;
  ASSERT_TRUE(p.read(*cfg).ok());
  EXPECT_FALSE(p.enabled);
  EXPECT_DOUBLE_EQ(p.w_ts, 0.7);
  CredibilityAssessor csa(p);
  csa.setEvidence(0, evidence(0.1, 10, 1.0));
  csa.setEvidence(1, evidence(1.0, 1000, 3.0));
  const std::vector<RobotId> arrivals = {0, 1, 0, 0, 1, 1, 0};
  for (std::size_t i = 0; i < arrivals.size(); ++i) csa.push(item(arrivals[i], i, static_cast<double>(i)));
  std::vector<std::uint64_t> seqs;
  while (auto r = csa.pop(100.0)) seqs.push_back(r->item.seq);
  EXPECT_EQ(seqs, (std::vector<std::uint64_t>{0, 1, 2, 3, 4, 5, 6}));

  auto bad = Config::fromString("server:\n  csa: maybe\n", "bad.yaml");
  ASSERT_TRUE(bad.ok());
  CredibilityParams q;
  Status s = q.read(*bad);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().find("server.csa"), std::string::npos) << s.error();
  CredibilityParams w;
  w.w_ts = w.w_mc = 0;
  EXPECT_FALSE(w.validate().ok());
}

TEST(Credibility, ServerParamsRoundTripThroughConfig) {
  CredibilityParams c;
  c.enabled = false;
  c.w_ts = 0.3;
  c.w_mc = 0.9;
  c.aging_per_s = 0.125;
  BookkeeperParams b;
  b.require_registration = true;
  b.anchor_min_keyframes = 12;
  b.stale_after_s = 7.5;
  ConfigWriter w;
  c.write(w);
  b.write(w);
  auto cfg = Config::fromString(w.yaml(), "written.yaml");
  ASSERT_TRUE(cfg.ok()) << cfg.error() << "\n" << w.yaml();
  CredibilityParams c2;
  BookkeeperParams b2;
  ASSERT_TRUE(c2.read(*cfg).ok());
  ASSERT_TRUE(b2.read(*cfg).ok());
  EXPECT_FALSE(c2.enabled);
  EXPECT_DOUBLE_EQ(c2.w_ts, 0.3);
  EXPECT_DOUBLE_EQ(c2.w_mc, 0.9);
  EXPECT_DOUBLE_EQ(c2.aging_per_s, 0.125);
  EXPECT_TRUE(b2.require_registration);
  EXPECT_EQ(b2.anchor_min_keyframes, 12);
  EXPECT_DOUBLE_EQ(b2.stale_after_s, 7.5);
  EXPECT_TRUE(cfg->unusedKeys().empty());
}
