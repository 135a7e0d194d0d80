// The relay's coordinator (relay_split.h): credibility order, the guaranteed
// floor per relayed robot and the relay's own minimum share; and on an emulated
// link, that the split really gives a relayed robot its floor.
#include <gtest/gtest.h>

#include "hermes/agent/relay_split.h"
#include "hermes/core/config.h"
#include "hermes/core/emulated_link.h"
#include "hermes/core/wire_format.h"
#include "hermes/core/wire_synthetic.h"

using namespace hermes;
using namespace hermes::agent;

TEST(RelaySplit, FloorPerRelayedRobotAndCredibilityOrder) {
  RelayParams p;
  std::vector<RelayStream> s(3);
  s[0] = {true, 1.0, 200e3, 3.0};   // the relay's own map
  s[1] = {false, 1.0, 100e3, 4.0};  // steady, well-connected relayed robot
  s[2] = {false, 0.5, 100e3, 2.0};  // half of its frames arrived twice, sparse map
  const auto out = splitUplink(p, s);
  ASSERT_EQ(out.size(), 3u);
  double sum = 0;
  for (const StreamShare& x : out) sum += x.weight;
  EXPECT_NEAR(sum, 1.0, 1e-9);
  EXPECT_EQ(out[0].guaranteed_Bps, 0.0);
  EXPECT_DOUBLE_EQ(out[1].guaranteed_Bps, 125000.0);  // 1 Mbit/s
  EXPECT_DOUBLE_EQ(out[2].guaranteed_Bps, 125000.0);
  EXPECT_GT(out[1].c, out[2].c);
  EXPECT_GT(out[1].weight, out[2].weight);
  EXPECT_NEAR(out[1].ts, 0.5, 1e-9);   // success 1 x 100/200
  EXPECT_NEAR(out[2].ts, 0.25, 1e-9);  // success 0.5 x 100/200
  EXPECT_NEAR(out[1].mc, 1.0, 1e-9);
  EXPECT_NEAR(out[2].mc, 0.5, 1e-9);
}

TEST(RelaySplit, OwnMapKeepsItsMinimumShare) {
  RelayParams p;
  p.own_min_share = 0.4;
  std::vector<RelayStream> s(3);
  s[0] = {true, 1.0, 0.0, 0.0};  // nothing known of its own map yet: least credible
  s[1] = {false, 1.0, 300e3, 5.0};
  s[2] = {false, 1.0, 300e3, 5.0};
  const auto out = splitUplink(p, s);
  EXPECT_NEAR(out[0].weight, 0.4, 1e-9);
  EXPECT_NEAR(out[1].weight, 0.3, 1e-9);
  EXPECT_NEAR(out[2].weight, 0.3, 1e-9);
  // Above its minimum it keeps what its credibility gives it.
  s[0] = {true, 1.0, 600e3, 5.0};
  s[1].obs_per_landmark = s[2].obs_per_landmark = 3.0;
  const auto out2 = splitUplink(p, s);
  EXPECT_GT(out2[0].weight, 0.4);
  EXPECT_TRUE(splitUplink(p, {}).empty());
}

TEST(RelaySplit, ParamsAreValidatedAndReadFromConfig) {
  auto cfg = Config::fromString("relay:\n  min_mbitps: 2.5\n  own_min_share: 0.2\n", "test.yaml");
  ASSERT_TRUE(cfg.ok());
  RelayParams p;
  ASSERT_TRUE(p.read(*cfg));
  EXPECT_DOUBLE_EQ(p.minBps(), 312500.0);
  auto bad = Config::fromString("relay:\n  own_min_share: 1.5\n", "test.yaml");
  ASSERT_TRUE(bad.ok());
  Status s = RelayParams{}.read(*bad);
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().find("relay.own_min_share"), std::string::npos) << s.error();
  RelayParams neg;
  neg.min_mbitps = -1;
  EXPECT_FALSE(neg.validate());
}

TEST(RelaySplit, EvidenceFromFrames) {
  SyntheticSubmapOptions o;
  o.keyframes = 3;
  o.keypoints_per_keyframe = 60;
  o.landmarks = 80;
  Submap sm = makeSyntheticSubmap(o);
  auto frame = encodeSubmap(sm);
  ASSERT_TRUE(frame.ok());
  StreamEvidence e;
  e.onFrame(*frame, 1.0, false);
  e.onFrame(*frame, 2.0, true);
  e.onFrame(*frame, 3.0, false);
  const RelayStream s = e.stream(3.0, false);
  EXPECT_NEAR(s.success_rate, 2.0 / 3.0, 1e-9);
  EXPECT_NEAR(s.bytes_per_s, 3.0 * double(frame->size()) / 2.0, 1e-6);
  EXPECT_NEAR(s.obs_per_landmark, double(sm.observationCount()) / double(sm.landmarks.size()), 1e-9);
}

namespace {

/// A 4 Mbit/s uplink whose slot 0 (the relay's own map, weight 0.9) holds 2 MB
/// and slot 1 (a relayed robot, weight 0.1, `guaranteed_Bps`) 250 kB, run for 1 s.
SharedLink floodedUplink(double guaranteed_Bps) {
  SharedLink link(LinkTrace::constant(4.0), 2, 1);
  link.setShare(0, 0.9, 0.0);
  link.setShare(1, 0.1, guaranteed_Bps);
  for (int i = 0; i <= 20; ++i) {
    LinkMessage m;
    m.sender = i < 20 ? 0 : 1;
    m.id = static_cast<std::uint64_t>(i);
    m.bytes = i < 20 ? 100000 : 250000;
    link.send(m, 0.0);
  }
  link.advanceTo(1.0);
  return link;
}

}  // namespace

TEST(RelaySplit, GuaranteedFloorHoldsOnTheLink) {
  // The relay's own map floods the link; the relayed robot still gets its
  // 1 Mbit/s while it has data waiting, plus its weight's part of what the
  // guarantee leaves (like tc htb).
  const SharedLink link = floodedUplink(125000.0);
  const double rate = link.servedBytes(1) / link.backloggedUpSeconds(1);
  EXPECT_NEAR(rate, 125000.0 + 0.1 * (500000.0 - 125000.0), 3000.0);
  EXPECT_NEAR(link.servedBytes(0) + link.servedBytes(1), 500000.0, 1500.0);  // work-conserving
  // Without the guarantee its weight alone gives it 0.4 Mbit/s.
  EXPECT_NEAR(floodedUplink(0.0).servedBytes(1), 50000.0, 3000.0);
}
