// The global pose over MQTT (mqtt_global_pose.h): round trip and layout, every
// rejection named with its offset, and a bounded deterministic fuzz (mutated
// valid payloads, random bytes, every length) where each outcome is a clean
// error or an update that passes validate() and encodes again; and server ->
// robot through a mosquitto broker (skipped without one).
// HERMES_FUZZ_SEED changes the seed.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <limits>
#include <random>

#include <chrono>
#include <thread>

#include "hermes/transport/mqtt_global_pose.h"
#include "hermes/transport/mqtt_links.h"
#include "hermes/transport/mqtt_messages.h"
#include "mosquitto_broker.h"

using namespace hermes;
using namespace hermes::transport;

namespace {

GlobalPoseMessage sample() {
  GlobalPoseMessage m;
  m.agent = agentUuid("MH_02_easy");
  m.update.session = 3;
  m.update.keyframes = 0x0102030405060708ull;
  m.update.keyframe_stamp = 1403636625.25;
  m.update.T_W_O = SE3(expSO3(Vec3(0.1, -0.4, 0.7)), Vec3(1.5, -2.25, 0.125));
  return m;
}

void putDoubleAt(std::vector<std::uint8_t>* b, std::size_t at, double d) {
  std::uint64_t v = 0;
  std::memcpy(&v, &d, sizeof v);
  for (int i = 0; i < 8; ++i) (*b)[at + i] = static_cast<std::uint8_t>(v >> (8 * i));
}

std::uint64_t fuzzSeed() {
  const char* s = std::getenv("HERMES_FUZZ_SEED");
  return s ? std::strtoull(s, nullptr, 10) : 19;
}

}  // namespace

TEST(MqttGlobalPose, RoundTripAndLayout) {
  const GlobalPoseMessage m = sample();
  auto bytes = encodeGlobalPose(m);
  ASSERT_TRUE(bytes.ok()) << bytes.error();
  ASSERT_EQ(bytes->size(), kGlobalPoseMessageBytes);
  EXPECT_EQ(std::string(bytes->begin(), bytes->begin() + 4), "HGPS");
  EXPECT_EQ((*bytes)[24], 3);     // session, little-endian
  EXPECT_EQ((*bytes)[28], 0x08);  // keyframes, little-endian
  auto back = decodeGlobalPose(bytes->data(), bytes->size());
  ASSERT_TRUE(back.ok()) << back.error();
  EXPECT_EQ(back->agent, m.agent);
  EXPECT_EQ(back->update.session, m.update.session);
  EXPECT_EQ(back->update.keyframes, m.update.keyframes);
  EXPECT_EQ(back->update.keyframe_stamp, m.update.keyframe_stamp);
  EXPECT_NEAR((back->update.T_W_O.translation() - m.update.T_W_O.translation()).norm(), 0, 1e-15);
  EXPECT_NEAR(rotationAngle((back->update.T_W_O.inverse() * m.update.T_W_O).rotation()), 0, 1e-12);
  EXPECT_EQ(*encodeGlobalPose(*back), *bytes);
  EXPECT_EQ(mqttTopic("MH_02_easy", MqttChannel::kGlobalPose), "hermes/MH_02_easy/global_pose");
  auto topic = parseMqttTopic("hermes/MH_02_easy/global_pose");
  ASSERT_TRUE(topic.ok()) << topic.error();
  EXPECT_EQ(topic->channel, MqttChannel::kGlobalPose);
}

TEST(MqttGlobalPose, EveryRejectionIsNamed) {
  GlobalPoseMessage bad = sample();
  bad.update.keyframe_stamp = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(encodeGlobalPose(bad).ok());
  const std::vector<std::uint8_t> good = *encodeGlobalPose(sample());
  struct Case {
    std::function<void(std::vector<std::uint8_t>*)> damage;
    std::string says;
  };
  const double inf = std::numeric_limits<double>::infinity();
  const std::vector<Case> cases = {
      {[](auto* b) { b->pop_back(); }, "payload of 99 bytes"},
      {[](auto* b) { b->push_back(0); }, "payload of 101 bytes"},
      {[](auto* b) { (*b)[1] = 'X'; }, "bad magic at offset 0"},
      {[](auto* b) { (*b)[4] = 2; }, "unsupported version 2 at offset 4"},
      {[](auto* b) { (*b)[6] = 1; }, "reserved bytes at offsets 5..7"},
      {[&](auto* b) { putDoubleAt(b, 36, inf); }, "keyframe stamp at offset 36"},
      {[&](auto* b) { putDoubleAt(b, 52, std::nan("")); }, "translation at offset 44"},
      {[&](auto* b) { putDoubleAt(b, 92, 2.0); }, "rotation at offset 68"},
      {[&](auto* b) { putDoubleAt(b, 76, inf); }, "rotation at offset 68"},
  };
  for (const Case& c : cases) {
    std::vector<std::uint8_t> b = good;
    c.damage(&b);
    auto r = decodeGlobalPose(b.data(), b.size());
    ASSERT_FALSE(r.ok()) << c.says;
    EXPECT_EQ(r.error().rfind("mqtt global pose: ", 0), 0u) << r.error();
    EXPECT_NE(r.error().find(c.says), std::string::npos) << r.error();
  }
  EXPECT_FALSE(decodeGlobalPose(nullptr, 5).ok());
  EXPECT_FALSE(decodeGlobalPose(nullptr, 0).ok());
}

TEST(MqttGlobalPose, FuzzedPayloadsDecodeCleanlyOrNotAtAll) {
  std::mt19937_64 rng(fuzzSeed());
  const std::vector<std::uint8_t> good = *encodeGlobalPose(sample());
  int decoded = 0, refused = 0;
  for (int i = 0; i < 20000; ++i) {
    std::vector<std::uint8_t> b;
    if (i % 4 == 0) {  // random bytes of any length, sometimes with the right header
      b.resize(rng() % 140);
      for (auto& x : b) x = static_cast<std::uint8_t>(rng());
      if (b.size() >= 8 && rng() % 2) std::memcpy(b.data(), good.data(), 8);
    } else {  // a valid payload with a few bytes changed
      b = good;
      for (int k = 1 + static_cast<int>(rng() % 4); k > 0; --k) b[rng() % b.size()] = static_cast<std::uint8_t>(rng());
    }
    auto r = decodeGlobalPose(b.data(), b.size());
    if (!r.ok()) {
      ++refused;
      EXPECT_EQ(r.error().rfind("mqtt global pose: ", 0), 0u) << r.error();
      continue;
    }
    ++decoded;
    ASSERT_TRUE(r->update.validate()) << r->update.validate().error();
    auto again = encodeGlobalPose(*r);
    ASSERT_TRUE(again.ok()) << again.error();
    auto twice = decodeGlobalPose(again->data(), again->size());
    ASSERT_TRUE(twice.ok()) << twice.error();
    EXPECT_EQ(twice->update.session, r->update.session);
    EXPECT_EQ(twice->update.keyframes, r->update.keyframes);
  }
  EXPECT_GT(decoded, 100);
  EXPECT_GT(refused, 1000);
}

TEST(MqttGlobalPose, ServerToRobotThroughTheBroker) {
  HERMES_REQUIRE_MOSQUITTO();
  test::MosquittoBroker broker(::testing::TempDir() + "/mqtt_global_pose");
  ASSERT_TRUE(broker.start()) << broker.error();
  const MqttParams p = test::testMqttParams(broker.port());
  auto server = MqttServerLink::create(p);
  ASSERT_TRUE(server.ok()) << server.error();
  auto robot = MqttAgentLink::create(p, "MH_02_easy", agentUuid("MH_02_easy"));
  ASSERT_TRUE(robot.ok()) << robot.error();
  (*server)->client().start();
  (*robot)->client().start();
  ASSERT_TRUE((*server)->client().waitConnected(3));
  ASSERT_TRUE((*robot)->client().waitConnected(3));
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while ((*robot)->client().stats().subscribed < 2 && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  const GlobalPoseMessage m = sample();
  GlobalPoseMessage foreign = sample();
  foreign.agent = agentUuid("MH_01_easy");
  ASSERT_TRUE((*server)->sendGlobalPose("MH_02_easy", foreign));
  ASSERT_TRUE((*server)->sendGlobalPose("MH_02_easy", m));
  EXPECT_FALSE((*server)->sendGlobalPose("not/a topic level", m));
  std::vector<GlobalPoseUpdate> got;
  std::vector<std::string> problems;
  while (got.empty() && std::chrono::steady_clock::now() < deadline) {
    AgentLinkEvents ev = (*robot)->poll();
    got.insert(got.end(), ev.global_poses.begin(), ev.global_poses.end());
    problems.insert(problems.end(), ev.problems.begin(), ev.problems.end());
    EXPECT_TRUE(ev.acks.empty());
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  ASSERT_EQ(got.size(), 1u);
  EXPECT_EQ(got[0].session, m.update.session);
  EXPECT_EQ(got[0].keyframes, m.update.keyframes);
  EXPECT_NEAR((got[0].T_W_O.translation() - m.update.T_W_O.translation()).norm(), 0, 1e-15);
  // The other robot's update on this robot's topic was reported, not taken.
  ASSERT_EQ(problems.size(), 1u);
  EXPECT_NE(problems[0].find("not this robot's"), std::string::npos) << problems[0];
  EXPECT_EQ((*robot)->malformed(), 1u);
}
