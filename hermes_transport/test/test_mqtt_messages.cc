// The MQTT payloads (acks, heartbeats) and topics: round trips, every rejection
// named, and a bounded deterministic fuzz (mutated valid payloads and random
// bytes) where each outcome is a clean error or a message that re-encodes to the
// same bytes. HERMES_FUZZ_SEED changes the seed.
#include <gtest/gtest.h>

#include <cstdlib>
#include <random>

#include "hermes/transport/mqtt_messages.h"

using namespace hermes;
using namespace hermes::transport;

namespace {

AckMessage sampleAck() {
  AckMessage a;
  a.status = AckStatus::kRejected;
  a.reason_code = 8;
  a.agent = agentUuid("robot_1");
  a.session = 7;
  a.seq = 0x0102030405060708ull;
  a.robot_id = 3;
  a.reason = "quota: robot 3 has 5 submaps waiting";
  return a;
}

HeartbeatMessage sampleHeartbeat() {
  HeartbeatMessage hb;
  hb.agent = agentUuid("MH_01");
  hb.session = 2;
  hb.next_seq = 41;
  hb.name = "MH_01";
  return hb;
}

std::uint64_t fuzzSeed() {
  const char* s = std::getenv("HERMES_FUZZ_SEED");
  return s ? std::strtoull(s, nullptr, 10) : 19;
}

}  // namespace

TEST(MqttMessages, AckRoundTripAndLayout) {
  const AckMessage a = sampleAck();
  auto bytes = encodeAck(a);
  ASSERT_TRUE(bytes.ok()) << bytes.error();
  EXPECT_EQ(bytes->size(), 42 + a.reason.size());
  EXPECT_EQ((*bytes)[0], 'H');
  EXPECT_EQ((*bytes)[28], 0x08);  // seq, little-endian
  auto back = decodeAck(bytes->data(), bytes->size());
  ASSERT_TRUE(back.ok()) << back.error();
  EXPECT_EQ(back->status, a.status);
  EXPECT_EQ(back->reason_code, a.reason_code);
  EXPECT_EQ(back->agent, a.agent);
  EXPECT_EQ(back->session, a.session);
  EXPECT_EQ(back->seq, a.seq);
  EXPECT_EQ(back->robot_id, a.robot_id);
  EXPECT_EQ(back->reason, a.reason);
  EXPECT_FALSE(back->acknowledges());

  AckMessage ok = a;
  ok.status = AckStatus::kDuplicate;
  ok.reason_code = 1;
  ok.reason = std::string(5000, 'x');  // cut to the limit
  bytes = encodeAck(ok);
  ASSERT_TRUE(bytes.ok());
  EXPECT_EQ(bytes->size(), 42 + kMaxAckReasonBytes);
  back = decodeAck(bytes->data(), bytes->size());
  ASSERT_TRUE(back.ok()) << back.error();
  EXPECT_TRUE(back->acknowledges());
  EXPECT_EQ(back->reason.substr(back->reason.size() - 3), "...");

  ok.status = AckStatus::kAccepted;  // accepted with a rejection's code
  ok.reason_code = 5;
  EXPECT_FALSE(encodeAck(ok).ok());
}

TEST(MqttMessages, AckRejectionsNameFieldAndOffset) {
  auto good = *encodeAck(sampleAck());
  auto expectError = [](std::vector<std::uint8_t> b, const std::string& part) {
    auto r = decodeAck(b.data(), b.size());
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().rfind("mqtt ack: ", 0), 0u) << r.error();
    EXPECT_NE(r.error().find(part), std::string::npos) << r.error();
  };
  expectError({}, "shorter than the 42-byte");
  expectError(std::vector<std::uint8_t>(good.begin(), good.begin() + 41), "shorter");
  auto b = good;
  b[1] = 'X';
  expectError(b, "magic at offset 0");
  b = good;
  b[4] = 9;
  expectError(b, "version 9 at offset 4");
  b = good;
  b[5] = 3;
  expectError(b, "unknown status 3 at offset 5");
  b = good;
  b[6] = 0;  // rejected + accepted's code
  expectError(b, "offset 6");
  b = good;
  b[7] = 1;
  expectError(b, "reserved byte at offset 7");
  b = good;
  b.push_back('!');
  expectError(b, "length field at offset 40");
  b = good;
  b.pop_back();
  expectError(b, "length field at offset 40");
  EXPECT_FALSE(decodeAck(nullptr, 50).ok());
}

TEST(MqttMessages, HeartbeatRoundTripAndRejections) {
  const HeartbeatMessage hb = sampleHeartbeat();
  auto bytes = encodeHeartbeat(hb);
  ASSERT_TRUE(bytes.ok()) << bytes.error();
  EXPECT_EQ(bytes->size(), 38 + hb.name.size());
  auto back = decodeHeartbeat(bytes->data(), bytes->size());
  ASSERT_TRUE(back.ok()) << back.error();
  EXPECT_EQ(back->agent, hb.agent);
  EXPECT_EQ(back->session, hb.session);
  EXPECT_EQ(back->next_seq, hb.next_seq);
  EXPECT_EQ(back->name, hb.name);

  HeartbeatMessage bad = hb;
  bad.name = "a/b";
  EXPECT_FALSE(encodeHeartbeat(bad).ok());
  bad.name = "";
  EXPECT_FALSE(encodeHeartbeat(bad).ok());

  auto b = *bytes;
  b[38] = '+';  // a wildcard in the name
  auto r = decodeHeartbeat(b.data(), b.size());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().find("name at offset 38"), std::string::npos) << r.error();
  b = *bytes;
  b[6] = 1;
  r = decodeHeartbeat(b.data(), b.size());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().find("reserved bytes at offsets 5..7"), std::string::npos) << r.error();
  b = *bytes;
  b[36] = 0;  // name length 0 but bytes follow
  r = decodeHeartbeat(b.data(), b.size());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().find("length field at offset 36"), std::string::npos) << r.error();
  r = decodeHeartbeat(bytes->data(), 10);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().rfind("mqtt heartbeat: ", 0), 0u) << r.error();
}

TEST(MqttMessages, Topics) {
  EXPECT_EQ(mqttTopic("MH_01", MqttChannel::kSubmap), "hermes/MH_01/submap");
  EXPECT_EQ(mqttTopicAllAgents(MqttChannel::kHeartbeat), "hermes/+/heartbeat");
  auto t = parseMqttTopic("hermes/robot-2.a/ack");
  ASSERT_TRUE(t.ok()) << t.error();
  EXPECT_EQ(t->agent, "robot-2.a");
  EXPECT_EQ(t->channel, MqttChannel::kAck);
  for (const char* bad : {"hermes/submap", "hermes//submap", "hermes/a/b/submap", "other/a/submap",
                          "hermes/a/pose", "hermes/a+/submap", "hermes/a", ""}) {
    auto r = parseMqttTopic(bad);
    EXPECT_FALSE(r.ok()) << bad;
  }
  EXPECT_TRUE(validateAgentName("agent_1"));
  EXPECT_FALSE(validateAgentName("agent 1"));
  EXPECT_FALSE(validateAgentName("#"));
  EXPECT_FALSE(validateAgentName(std::string(65, 'a')));
}

// Mutants of valid payloads and random byte strings: a clean error, or a
// message that encodes back to exactly the bytes decoded.
TEST(MqttMessages, FuzzedPayloadsGiveCleanErrorsOrExactMessages) {
  std::mt19937_64 rng(fuzzSeed());
  const std::vector<std::vector<std::uint8_t>> seeds_ack = {
      *encodeAck(sampleAck()),
      *encodeAck(AckMessage{AckStatus::kAccepted, 0, agentUuid("x"), 1, 2, 3, ""})};
  const std::vector<std::uint8_t> seed_hb = *encodeHeartbeat(sampleHeartbeat());
  std::size_t decoded = 0, rejected = 0;
  for (int it = 0; it < 200000; ++it) {
    const bool ack = it % 2 == 0;
    std::vector<std::uint8_t> b = ack ? seeds_ack[rng() % seeds_ack.size()] : seed_hb;
    if (rng() % 20 == 0) {  // random bytes, sometimes behind a valid magic and version
      b.resize(rng() % 80);
      for (auto& x : b) x = static_cast<std::uint8_t>(rng());
      if (b.size() >= 5 && rng() % 2) {
        const char* magic = ack ? "HACK" : "HHBT";
        std::copy(magic, magic + 4, b.begin());
        b[4] = 1;
      }
    } else {
      const int edits = 1 + static_cast<int>(rng() % 3);
      for (int e = 0; e < edits; ++e) {
        const std::size_t at = b.empty() ? 0 : rng() % b.size();
        switch (rng() % 5) {
          case 0: if (!b.empty()) b[at] ^= static_cast<std::uint8_t>(1u << (rng() % 8)); break;
          case 1: if (!b.empty()) b[at] = static_cast<std::uint8_t>(rng()); break;
          case 2: b.resize(rng() % (b.size() + 1)); break;
          case 3: b.insert(b.begin() + at, static_cast<std::uint8_t>(rng())); break;
          case 4: if (!b.empty()) b.erase(b.begin() + at); break;
        }
      }
    }
    // A clean error with the decoder's prefix, or a message that encodes back to `b`.
    auto check = [&](auto decode, auto encode, const std::string& prefix) {
      auto r = decode(b.data(), b.size());
      if (!r.ok()) {
        ++rejected;
        return r.error().rfind(prefix, 0) == 0 ? std::string() : r.error();
      }
      ++decoded;
      auto again = encode(*r);
      if (!again.ok()) return again.error();
      return *again == b ? std::string() : prefix + "decoded, but encodes to other bytes";
    };
    const std::string problem = ack ? check(decodeAck, encodeAck, "mqtt ack: ")
                                    : check(decodeHeartbeat, encodeHeartbeat, "mqtt heartbeat: ");
    ASSERT_TRUE(problem.empty()) << problem << " (iteration " << it << ")";
  }
  EXPECT_GT(decoded, 1000u);  // mutants of the variable fields still decode
  EXPECT_GT(rejected, 50000u);
  std::printf("fuzz: %zu decoded exactly, %zu rejected cleanly\n", decoded, rejected);
}
