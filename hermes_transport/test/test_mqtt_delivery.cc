// Exactly-once submap delivery over MQTT through a real mosquitto broker on a
// loopback port, end to end with the real UplinkSender (disk spool, resends) on
// each robot and the real SubmapReceiver (bookkeeper dedup) on the server:
// normal delivery of three robots; the broker killed (SIGKILL, no persistence:
// it forgets every session and queued message) and restarted mid-run while a
// robot process is restarted too; a robot that reconnects and finds its
// acknowledgements in its persistent session; malformed payloads answered with
// a reason and never disturbing the others. Skipped only without the binary.
#include <gtest/gtest.h>

#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <set>
#include <thread>

#include "hermes/agent/uplink_sender.h"
#include "hermes/core/wire_format.h"
#include "hermes/core/wire_synthetic.h"
#include "hermes/server/submap_receiver.h"
#include "hermes/transport/mqtt_links.h"
#include "mosquitto_broker.h"

using namespace hermes;
using namespace hermes::transport;
using hermes::transport::test::MosquittoBroker;
using hermes::transport::test::testMqttParams;

namespace {

using Key = std::tuple<std::string, std::uint32_t, std::uint64_t>;  // robot name, session, seq

std::vector<std::uint8_t> frameFor(const std::string& robot, std::uint32_t session, std::uint64_t seq) {
  SyntheticSubmapOptions o;
  o.keyframes = 3;
  o.keypoints_per_keyframe = 60;
  o.landmarks = 80;
  o.seed = std::hash<std::string>()(robot) ^ (seq * 7919 + session);
  Submap s = makeSyntheticSubmap(o);
  s.header.agent = agentUuid(robot);
  s.header.session = session;
  s.header.seq = seq;
  auto f = encodeSubmap(s, WireOptions{});
  EXPECT_TRUE(f.ok()) << f.error();
  return *f;
}

/// The edge server's receiving end: link + the real receiver and bookkeeper.
struct ServerSide {
  Bookkeeper books;
  std::map<Key, int> applied;  ///< times each submap reached the sink
  std::map<Uuid, std::string> names;  ///< from the topics (the receiver checks uuid == agentUuid(topic))
  SubmapReceiver rx;
  std::unique_ptr<MqttServerLink> link;
  std::vector<ReceiveResult> rejected;
  std::vector<std::string> problems;

  explicit ServerSide(const MqttParams& p)
      : rx(&books, [this](ReceivedSubmap&& s) {
          const auto& h = s.submap.header;
          ++applied[{names.at(h.agent), h.session, h.seq}];
        }) {
    auto l = MqttServerLink::create(p);
    EXPECT_TRUE(l.ok()) << l.error();
    link = std::move(*l);
    link->client().start();
  }
  void step(double now) {
    ServerLinkEvents ev = link->poll();
    problems.insert(problems.end(), ev.problems.begin(), ev.problems.end());
    for (const IncomingFrame& f : ev.frames) {
      names[agentUuid(f.agent)] = f.agent;
      const ReceiveResult r = link->handle(f, [&](const std::uint8_t* d, std::size_t n, const SubmapHeader* c) {
        return rx.receive(d, n, c, now);
      });
      if (r.verdict == ArrivalVerdict::kRejected) rejected.push_back(r);
    }
  }
};

/// One robot process: its link and its real UplinkSender over a disk spool.
struct AgentSide {
  std::string name;
  agent::UplinkParams up;
  MqttParams mqtt;
  std::unique_ptr<MqttAgentLink> link;
  std::unique_ptr<agent::UplinkSender> sender;
  std::uint32_t session = 0;
  std::uint64_t next_seq = 0;
  std::set<Key> submitted;
  std::vector<std::string> problems;
  std::size_t resend_all = 0, rejections = 0, sends = 0, resends = 0;
  std::size_t pending_at_close = 0, malformed = 0;  ///< as of close()

  AgentSide(std::string robot, const MqttParams& p) : name(std::move(robot)), mqtt(p) {
    // Per test: ctest runs the tests of this file as parallel processes.
    up.buffer.dir = ::testing::TempDir() + "/mqtt_spool_" +
                    ::testing::UnitTest::GetInstance()->current_test_info()->name() + "_" + name;
    std::filesystem::remove_all(up.buffer.dir);
    up.buffer.fsync = false;
    up.buffer.resend_timeout_s = 2.0;
  }
  ~AgentSide() { close(); }
  /// Starts the process: link (threaded) and sender over the spool on disk.
  void open(bool new_session) {
    auto l = MqttAgentLink::create(mqtt, name, agentUuid(name));
    ASSERT_TRUE(l.ok()) << l.error();
    link = std::move(*l);
    link->client().start();
    auto s = agent::UplinkSender::create(up, [this](std::uint32_t, std::uint64_t,
                                                    const std::vector<std::uint8_t>& frame) {
      link->sendSubmap(frame);  // refused while offline: the spool resends
    });
    ASSERT_TRUE(s.ok()) << s.error();
    sender = std::make_unique<agent::UplinkSender>(std::move(*s));
    if (new_session) {
      session = *sender->buffer().newSession();
      next_seq = 0;
    }
  }
  /// Ends the process (its spool stays on disk).
  void close() {
    if (sender) {
      sends += sender->stats().sends;
      resends += sender->stats().resends;
      pending_at_close = sender->buffer().pendingCount();
    }
    if (link) malformed += link->malformed();
    sender.reset();
    link.reset();
  }
  void submitNext(double now) {
    ASSERT_TRUE(sender->submit(session, next_seq, frameFor(name, session, next_seq), now));
    submitted.insert({name, session, next_seq});
    ++next_seq;
  }
  void step(double now, bool poll_sender = true) {
    AgentLinkEvents ev = link->poll();
    problems.insert(problems.end(), ev.problems.begin(), ev.problems.end());
    if (ev.resend_all) {
      ++resend_all;
      sender->onReconnect();
    }
    for (const AckMessage& a : ev.acks) {
      if (a.acknowledges()) EXPECT_TRUE(sender->onAck(a.session, a.seq, now));
      else ++rejections;
    }
    if (poll_sender) sender->poll(now);
  }
  bool drained() const { return (sender ? sender->buffer().pendingCount() : pending_at_close) == 0; }
};

double now0 = mqttClock();
double now() { return mqttClock() - now0; }

bool containsText(const std::vector<std::string>& v, const std::string& part) {
  for (const std::string& s : v)
    if (s.find(part) != std::string::npos) return true;
  return false;
}

void expectExactlyOnce(const ServerSide& server, const std::vector<AgentSide*>& agents) {
  std::set<Key> all;
  for (const AgentSide* a : agents) all.insert(a->submitted.begin(), a->submitted.end());
  std::set<Key> got;
  for (const auto& [k, n] : server.applied) {
    EXPECT_EQ(n, 1) << std::get<0>(k) << " session " << std::get<1>(k) << " seq " << std::get<2>(k)
                    << " applied " << n << " times";
    got.insert(k);
  }
  EXPECT_EQ(got, all);  // nothing lost, nothing invented
  for (const AgentSide* a : agents) EXPECT_TRUE(a->drained()) << a->name << " still has unacked submaps";
}

/// Robots a1, a2, a3 submitting in step with the server's steps.
struct Fleet {
  std::vector<std::unique_ptr<AgentSide>> agents;

  explicit Fleet(const MqttParams& p) {
    for (const char* n : {"a1", "a2", "a3"}) {
      agents.push_back(std::make_unique<AgentSide>(n, p));
      agents.back()->open(true);
    }
  }
  /// Each robot submits `submaps`, one every `period` s, until every spool has
  /// drained or `limit_s` passed; `hook(seconds since start)` runs first in every
  /// step (kills, restarts) and returns false while the run may not end yet.
  /// Returns the seconds taken.
  double run(ServerSide& server, int submaps, double period, double limit_s,
             const std::function<bool(double)>& hook = [](double) { return true; }) {
    const double start = now();
    int submitted = 0;
    while (now() - start < limit_s) {
      const double t = now();
      bool all = hook(t - start);
      if (submitted < submaps && t - start >= period * submitted) {
        for (auto& a : agents) a->submitNext(t);
        ++submitted;
      }
      server.step(t);
      all = all && submitted == submaps;
      for (auto& a : agents) {
        a->step(t);
        all = all && a->drained();
      }
      if (all) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    return now() - start;
  }
  /// Ends every robot's process; the robots for expectExactlyOnce().
  std::vector<AgentSide*> close() {
    std::vector<AgentSide*> raw;
    for (auto& a : agents) {
      a->close();
      raw.push_back(a.get());
    }
    return raw;
  }
  std::size_t sum(std::size_t AgentSide::*field) const {
    std::size_t n = 0;
    for (const auto& a : agents) n += (*a).*field;
    return n;
  }
};

}  // namespace

TEST(MqttDelivery, ThreeAgentsExactlyOnce) {
  HERMES_REQUIRE_MOSQUITTO();
  MosquittoBroker broker(::testing::TempDir() + "/mqtt_delivery_normal");
  ASSERT_TRUE(broker.start()) << broker.error();
  const MqttParams p = testMqttParams(broker.port());
  ServerSide server(p);
  ASSERT_TRUE(server.link->client().waitConnected(3)) << server.link->client().lastError();
  Fleet fleet(p);
  const double took = fleet.run(server, 10, 0.05, 20);
  expectExactlyOnce(server, fleet.close());
  EXPECT_EQ(server.rx.stats().accepted, 30u);
  EXPECT_TRUE(server.rejected.empty());
  std::printf("3 agents x 10 submaps delivered and acknowledged in %.2f s; sends %zu, resends %zu, "
              "server duplicates %zu\n",
              took, fleet.sum(&AgentSide::sends), fleet.sum(&AgentSide::resends), server.rx.stats().duplicates);
}

// The failure test: three robots and the server; the broker is killed
// (SIGKILL, persistence false: every session and queued message is gone) and
// restarted mid-run, and one robot process is restarted (new session, its
// unacked submaps of the old one still in its spool). Every submap is applied
// exactly once.
TEST(MqttDelivery, BrokerKilledAndRestartedAndAgentRestartedExactlyOnce) {
  HERMES_REQUIRE_MOSQUITTO();
  MosquittoBroker broker(::testing::TempDir() + "/mqtt_delivery_restart");
  ASSERT_TRUE(broker.start()) << broker.error();
  const MqttParams p = testMqttParams(broker.port());
  ServerSide server(p);
  ASSERT_TRUE(server.link->client().waitConnected(3));
  Fleet fleet(p);
  const int kSubmaps = 24;
  bool killed = false, restarted = false, agent_restarted = false;
  std::size_t applied_before_kill = 0;
  const double took = fleet.run(server, kSubmaps, 0.15, 40, [&](double rel) {
    if (!killed && rel >= 0.8) {
      applied_before_kill = server.applied.size();
      broker.kill();
      killed = true;
    }
    if (killed && !restarted && rel >= 2.0) restarted = broker.start();
    if (!agent_restarted && rel >= 2.6) {  // robot a2's process dies and starts again
      fleet.agents[1]->close();
      fleet.agents[1]->open(true);
      agent_restarted = true;
    }
    return agent_restarted;
  });
  for (const auto& a : fleet.agents)
    EXPECT_TRUE(containsText(a->problems, "lost")) << a->name << " did not notice the broker's death";
  expectExactlyOnce(server, fleet.close());
  ASSERT_TRUE(killed && restarted && agent_restarted) << broker.error();
  EXPECT_EQ(server.rx.stats().accepted, 3u * kSubmaps);
  EXPECT_GT(applied_before_kill, 0u);
  EXPECT_LT(applied_before_kill, 3u * kSubmaps);  // the kill really was mid-run
  EXPECT_GE(fleet.sum(&AgentSide::resend_all), 3u);  // every robot resent its backlog after the broker forgot it
  EXPECT_GE(server.link->client().stats().losses, 1u);
  EXPECT_TRUE(containsText(server.problems, "lost"));
  std::set<std::uint32_t> a2_sessions;
  for (const Key& k : fleet.agents[1]->submitted) a2_sessions.insert(std::get<1>(k));
  EXPECT_EQ(a2_sessions.size(), 2u);  // the restarted robot used a new session
  std::printf("broker killed at 0.8 s (%zu/%d applied), back at 2.0 s, robot a2 restarted at 2.6 s: "
              "all %zu submaps applied once after %.2f s; %zu sends, %zu resends, %zu backlog "
              "resends, %zu duplicates dropped by the server\n",
              applied_before_kill, 3 * kSubmaps, server.applied.size(), took, fleet.sum(&AgentSide::sends),
              fleet.sum(&AgentSide::resends), fleet.sum(&AgentSide::resend_all), server.rx.stats().duplicates);
}

// A robot publishes, goes away before the server answers, and reconnects with
// the same client id: its acknowledgements were kept in its persistent session
// and arrive without a single resend.
TEST(MqttDelivery, ReconnectingAgentGetsItsAcksFromThePersistentSession) {
  HERMES_REQUIRE_MOSQUITTO();
  MosquittoBroker broker(::testing::TempDir() + "/mqtt_delivery_session");
  ASSERT_TRUE(broker.start()) << broker.error();
  const MqttParams p = testMqttParams(broker.port());
  ServerSide server(p);
  ASSERT_TRUE(server.link->client().waitConnected(3));
  AgentSide a("a1", p);
  a.open(true);
  ASSERT_TRUE(a.link->client().waitConnected(3));
  const double deadline = now() + 5;
  while (a.link->client().stats().subscribed < 1 && now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  for (int i = 0; i < 5; ++i) a.submitNext(now());
  while (a.link->client().stats().completed < 5 && now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  ASSERT_EQ(a.link->client().stats().completed, 5u);  // the broker has them (PUBCOMP)
  a.close();                                           // the robot goes away
  while (server.applied.size() < 5 && now() < deadline) {
    server.step(now());
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  ASSERT_EQ(server.applied.size(), 5u);
  while (server.link->client().stats().completed < 5 && now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));  // acks in the broker's hands
  a.open(false);  // same process identity, spool with 5 unacked submaps
  ASSERT_EQ(a.sender->buffer().pendingCount(), 5u);
  // The acks are collected before any is applied: onAck() lets the sender send
  // what is still unacknowledged, and nothing may need to be.
  bool session_present = false;
  std::vector<AckMessage> acks;
  while (acks.size() < 5 && now() < deadline + 5) {
    AgentLinkEvents ev = a.link->poll();
    if (ev.connected_now) session_present = !ev.resend_all;
    acks.insert(acks.end(), ev.acks.begin(), ev.acks.end());
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  ASSERT_EQ(acks.size(), 5u);
  EXPECT_EQ(a.sender->stats().sends, 0u);  // all five arrived before anything was sent again
  for (const AckMessage& ack : acks) ASSERT_TRUE(a.sender->onAck(ack.session, ack.seq, now()));
  EXPECT_TRUE(a.drained());
  EXPECT_TRUE(session_present);
  EXPECT_EQ(a.link->client().stats().sessions_resumed, 1u);
  expectExactlyOnce(server, {&a});
}

// A rogue client publishes garbage, a truncated frame and another robot's frame
// on its own topic, a broken heartbeat, and a garbage ack on a robot's ack
// topic. Each is answered with a reason (frames) or reported (the rest); the two
// honest robots deliver exactly once meanwhile.
TEST(MqttDelivery, MalformedPayloadsAreRejectedWithAReasonAndDisturbNoOne) {
  HERMES_REQUIRE_MOSQUITTO();
  MosquittoBroker broker(::testing::TempDir() + "/mqtt_delivery_malformed");
  ASSERT_TRUE(broker.start()) << broker.error();
  const MqttParams p = testMqttParams(broker.port());
  ServerSide server(p);
  ASSERT_TRUE(server.link->client().waitConnected(3));
  AgentSide a1("a1", p), a2("a2", p);
  a1.open(true);
  a2.open(true);
  auto rogue_or = MqttClient::create(p, "rogue-client", {{mqttTopic("rogue", MqttChannel::kAck), 2}});
  ASSERT_TRUE(rogue_or.ok()) << rogue_or.error();
  MqttClient& rogue = **rogue_or;
  ASSERT_TRUE(rogue.waitConnected(3));
  ASSERT_TRUE(a1.link->client().waitConnected(3));
  const double deadline = now() + 5;
  while (rogue.stats().subscribed < 1 || a1.link->client().stats().subscribed < 1)
    if (now() > deadline) FAIL() << "no SUBACK"; else rogue.pump(5);

  const std::string rogue_submap = mqttTopic("rogue", MqttChannel::kSubmap);
  auto truncated = frameFor("rogue", 0, 0);
  truncated.resize(truncated.size() / 2);
  ASSERT_TRUE(rogue.publish(rogue_submap, {'n', 'o', 't', ' ', 'a', ' ', 'f', 'r', 'a', 'm', 'e'}, 2));
  ASSERT_TRUE(rogue.publish(rogue_submap, truncated, 2));
  ASSERT_TRUE(rogue.publish(rogue_submap, frameFor("a2", 0, 99), 2));  // a2's identity
  ASSERT_TRUE(rogue.publish(mqttTopic("rogue", MqttChannel::kHeartbeat), {1, 2, 3}, 0));
  ASSERT_TRUE(rogue.publish(mqttTopic("a1", MqttChannel::kAck), {'H', 'A', 'C', 'K', 1}, 2));

  std::vector<AckMessage> rogue_acks;
  int submitted = 0;
  while (now() < deadline + 10) {
    const double t = now();
    if (submitted < 6) {
      a1.submitNext(t);
      a2.submitNext(t);
      ++submitted;
    }
    server.step(t);
    a1.step(t);
    a2.step(t);
    rogue.pump(2);
    for (MqttEvent& e : rogue.drain())
      if (e.kind == MqttEvent::Kind::kMessage) rogue_acks.push_back(*decodeAck(e.payload.data(), e.payload.size()));
    if (submitted == 6 && a1.drained() && a2.drained() && rogue_acks.size() >= 3 &&
        containsText(server.problems, "heartbeat") && a1.link->malformed() >= 1)
      break;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  a1.close();
  a2.close();
  expectExactlyOnce(server, {&a1, &a2});
  ASSERT_EQ(rogue_acks.size(), 3u);
  for (const AckMessage& ack : rogue_acks) {
    EXPECT_EQ(ack.status, AckStatus::kRejected);
    EXPECT_FALSE(ack.reason.empty());
  }
  EXPECT_EQ(rogue_acks[0].reason_code, static_cast<std::uint8_t>(ReceiveCode::kMalformed));
  EXPECT_NE(rogue_acks[0].reason.find("wire: "), std::string::npos) << rogue_acks[0].reason;
  EXPECT_EQ(rogue_acks[1].reason_code, static_cast<std::uint8_t>(ReceiveCode::kMalformed));
  EXPECT_EQ(rogue_acks[2].reason_code, static_cast<std::uint8_t>(ReceiveCode::kRoutingMismatch));
  EXPECT_NE(rogue_acks[2].reason.find("topic of robot 'rogue'"), std::string::npos) << rogue_acks[2].reason;
  EXPECT_EQ(server.applied.count({"a2", 0, 99}), 0u);  // the stolen identity applied nothing
  EXPECT_TRUE(containsText(server.problems, "malformed heartbeat on hermes/rogue/heartbeat"));
  EXPECT_EQ(a1.malformed, 1u);
  EXPECT_TRUE(containsText(a1.problems, "malformed payload on hermes/a1/ack"));
  EXPECT_EQ(a1.rejections + a2.rejections, 0u);
  for (const ReceiveResult& r : server.rejected) std::printf("rejected: %s: %s\n", toString(r.code), r.reason.c_str());
}
