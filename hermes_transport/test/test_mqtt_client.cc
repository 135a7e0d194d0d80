// MqttClient against a real mosquitto broker on a loopback port: the error when
// the broker cannot be reached, delivery, the bounded inbox, losing the broker
// and getting it back (with and without the broker keeping our session), and
// username/password, TLS with a client certificate. Skipped only when the
// mosquitto binary (or, for TLS, the openssl command) is missing.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <thread>

#include "hermes/transport/mqtt_client.h"
#include "mosquitto_broker.h"

using namespace hermes;
using namespace hermes::transport;
using hermes::transport::test::BrokerOptions;
using hermes::transport::test::MosquittoBroker;
using hermes::transport::test::testMqttParams;

namespace {

std::unique_ptr<MqttClient> client(const MqttParams& p, const std::string& id,
                                   std::vector<MqttSubscription> subs = {}) {
  auto c = MqttClient::create(p, id, std::move(subs));
  EXPECT_TRUE(c.ok()) << c.error();
  return c.ok() ? std::move(*c) : nullptr;
}

/// Pumps both clients until `done` or `seconds` pass.
template <class F>
bool pumpUntil(std::initializer_list<MqttClient*> clients, double seconds, F done) {
  const double deadline = mqttClock() + seconds;
  while (mqttClock() < deadline) {
    for (MqttClient* c : clients) c->pump(5);
    if (done()) return true;
  }
  return false;
}

/// Polls `done` every 10 ms for up to `seconds`.
template <class F>
bool waitFor(double seconds, F done) {
  const double deadline = mqttClock() + seconds;
  while (!done()) {
    if (mqttClock() > deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return true;
}

std::size_t countKind(const std::vector<MqttEvent>& events, MqttEvent::Kind kind) {
  std::size_t n = 0;
  for (const MqttEvent& e : events) n += e.kind == kind;
  return n;
}

}  // namespace

TEST(MqttClient, UnreachableBrokerGivesAClearError) {
  const int port = MosquittoBroker::freePort();
  auto c = client(testMqttParams(port), "hermes-test-unreachable");
  ASSERT_TRUE(c);
  Status s = c->waitConnected(0.5);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().find("MQTT broker 127.0.0.1:" + std::to_string(port) + " cannot be reached"),
            std::string::npos)
      << s.error();
  EXPECT_NE(s.error().find("refused"), std::string::npos) << s.error();
  EXPECT_GE(c->stats().failed_attempts, 2u);  // retried with backoff
  EXPECT_FALSE(c->publish("t", {1, 2}, 2).ok());
  EXPECT_EQ(c->stats().refused, 1u);
}

TEST(MqttClient, DeliversQos2AndBoundsTheInbox) {
  HERMES_REQUIRE_MOSQUITTO();
  MosquittoBroker broker(::testing::TempDir() + "/mqtt_client_deliver");
  ASSERT_TRUE(broker.start()) << broker.error();
  MqttParams p = testMqttParams(broker.port());
  p.inbox_capacity = 5;
  auto rx = client(p, "hermes-test-rx", {{"t/#", 2}});
  auto tx = client(p, "hermes-test-tx");
  ASSERT_TRUE(rx && tx);
  ASSERT_TRUE(rx->waitConnected(3)) << rx->lastError();
  ASSERT_TRUE(tx->waitConnected(3)) << tx->lastError();
  auto events = rx->drain();
  ASSERT_EQ(countKind(events, MqttEvent::Kind::kConnected), 1u);
  ASSERT_TRUE(pumpUntil({rx.get()}, 5, [&] { return rx->stats().subscribed == 1; }));  // the SUBACK
  for (int i = 0; i < 20; ++i)
    ASSERT_TRUE(tx->publish("t/" + std::to_string(i), {static_cast<std::uint8_t>(i), 0xff}, 2));
  // The receiver may have all 20 before the sender has its last PUBCOMP: wait for both.
  ASSERT_TRUE(pumpUntil({rx.get(), tx.get()}, 10, [&] {
    return rx->stats().received == 20 && tx->stats().completed == 20;
  })) << rx->stats().received << " received, " << tx->stats().completed << " completed";
  EXPECT_EQ(tx->stats().completed, 20u);  // PUBCOMP for every QoS 2 publish
  events = rx->drain();
  ASSERT_EQ(events.size(), 5u);  // the capacity; the rest dropped and counted
  EXPECT_EQ(rx->stats().dropped, 15u);
  EXPECT_EQ(events[0].topic, "t/0");
  EXPECT_EQ(events[4].payload, (std::vector<std::uint8_t>{4, 0xff}));
}

// The broker dies (SIGKILL) and comes back: the client notices, retries with
// backoff and reconnects by itself. Without persistence the broker forgot our
// session; with it, a QoS 2 message published while we were away still arrives.
TEST(MqttClient, ReconnectsAfterBrokerRestartWithAndWithoutPersistence) {
  HERMES_REQUIRE_MOSQUITTO();
  for (bool persistence : {false, true}) {
    SCOPED_TRACE(persistence ? "persistence true" : "persistence false");
    BrokerOptions o;
    o.persistence = persistence;
    MosquittoBroker broker(::testing::TempDir() + "/mqtt_client_restart", o);
    ASSERT_TRUE(broker.start()) << broker.error();
    const MqttParams p = testMqttParams(broker.port());
    auto rx = client(p, "hermes-test-rx-restart", {{"q", 2}});
    ASSERT_TRUE(rx);
    rx->start();  // threaded mode
    ASSERT_TRUE(rx->waitConnected(3)) << rx->lastError();
    ASSERT_TRUE(waitFor(5, [&] { return rx->stats().subscribed == 1; }));  // SUBACK
    rx->stop();
    rx.reset();  // away (clean DISCONNECT: the session stays)
    {
      auto tx = client(p, "hermes-test-tx-restart");
      ASSERT_TRUE(tx->waitConnected(3));
      ASSERT_TRUE(tx->publish("q", {42}, 2));
      ASSERT_TRUE(pumpUntil({tx.get()}, 3, [&] { return tx->stats().completed == 1; }));
    }
    if (persistence) {  // SIGKILL loses what is not saved: wait for the next autosave (1 s)
      const auto published = std::filesystem::file_time_type::clock::now();
      ASSERT_TRUE(broker.waitSaved(published, 10)) << "no autosave of the broker's database";
    }
    broker.kill();
    ASSERT_TRUE(broker.start()) << broker.error();
    rx = client(p, "hermes-test-rx-restart", {{"q", 2}});
    rx->start();
    ASSERT_TRUE(rx->waitConnected(3)) << rx->lastError();
    std::vector<MqttEvent> events;
    auto collect = [&] {
      for (MqttEvent& e : rx->drain()) events.push_back(std::move(e));
      return countKind(events, MqttEvent::Kind::kMessage) > 0;
    };
    waitFor(persistence ? 5 : 0.5, collect);  // the queued message, if the session kept it
    collect();
    ASSERT_GE(events.size(), 1u);
    EXPECT_EQ(events[0].kind, MqttEvent::Kind::kConnected);
    EXPECT_EQ(events[0].session_present, persistence);
    EXPECT_EQ(countKind(events, MqttEvent::Kind::kMessage), persistence ? 1u : 0u);

    // Lost while connected: a kConnectionLost event, reconnection by itself.
    broker.kill();
    EXPECT_TRUE(waitFor(5, [&] { return !rx->connected(); }));
    ASSERT_TRUE(broker.start()) << broker.error();
    ASSERT_TRUE(rx->waitConnected(5)) << rx->lastError();
    events = rx->drain();
    EXPECT_EQ(countKind(events, MqttEvent::Kind::kConnectionLost), 1u);
    EXPECT_EQ(countKind(events, MqttEvent::Kind::kConnected), 1u);
    EXPECT_GE(rx->stats().losses, 1u);
  }
}

TEST(MqttClient, UsernameAndPassword) {
  HERMES_REQUIRE_MOSQUITTO();
  const std::string passwd_tool = "/usr/bin/mosquitto_passwd";
  if (!std::filesystem::exists(passwd_tool)) GTEST_SKIP() << "no " << passwd_tool;
  const std::string dir = ::testing::TempDir() + "/mqtt_client_auth_files";
  std::filesystem::create_directories(dir);
  const std::string users = dir + "/users";
  std::filesystem::remove(users);
  ASSERT_EQ(std::system((passwd_tool + " -b -c " + users + " robots s3cret").c_str()), 0);
  BrokerOptions o;
  o.password_file = users;
  MosquittoBroker broker(::testing::TempDir() + "/mqtt_client_auth", o);
  ASSERT_TRUE(broker.start()) << broker.error();
  MqttParams p = testMqttParams(broker.port());
  p.username = "robots";
  p.password_file = dir + "/pw";
  std::ofstream(p.password_file) << "wrong\n";
  auto bad = client(p, "hermes-test-auth-bad");
  Status s = bad->waitConnected(1);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().find("refused"), std::string::npos) << s.error();
  std::ofstream(p.password_file) << "s3cret\n";
  auto good = client(p, "hermes-test-auth-good");
  EXPECT_TRUE(good->waitConnected(3)) << good->lastError();
}

namespace {

/// A CA, and a server and a client certificate it signed (EC P-256, made with the
/// openssl command); false when a step failed.
bool makeCertificates(const std::string& dir, const std::string& ca_name) {
  std::filesystem::create_directories(dir);
  const std::string key = " -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes";
  std::ofstream(dir + "/server.ext") << "subjectAltName=DNS:localhost,IP:127.0.0.1\n";
  const std::vector<std::string> steps = {
      "openssl req -x509" + key + " -keyout " + dir + "/ca.key -out " + dir + "/ca.pem -days 2 -subj /CN=" + ca_name,
      "openssl req" + key + " -keyout " + dir + "/server.key -out " + dir + "/server.csr -subj /CN=localhost",
      "openssl x509 -req -in " + dir + "/server.csr -CA " + dir + "/ca.pem -CAkey " + dir + "/ca.key -CAcreateserial -out " +
          dir + "/server.pem -days 2 -extfile " + dir + "/server.ext",
      "openssl req" + key + " -keyout " + dir + "/client.key -out " + dir + "/client.csr -subj /CN=robot",
      "openssl x509 -req -in " + dir + "/client.csr -CA " + dir + "/ca.pem -CAkey " + dir + "/ca.key -CAcreateserial -out " +
          dir + "/client.pem -days 2"};
  for (const std::string& cmd : steps)
    if (std::system((cmd + " > " + dir + "/openssl.log 2>&1").c_str()) != 0) return false;
  return true;
}

}  // namespace

// The broker speaks TLS only and wants a client certificate: the client with
// the right CA and its certificate connects and delivers; one that trusts
// another CA, or speaks plain MQTT, does not get in and says why.
TEST(MqttClient, TlsWithClientCertificate) {
  HERMES_REQUIRE_MOSQUITTO();
  if (std::system("openssl version > /dev/null 2>&1") != 0) GTEST_SKIP() << "no openssl command";
  const std::string dir = ::testing::TempDir() + "/mqtt_client_tls_files", other = dir + "/other";
  std::filesystem::remove_all(dir);
  ASSERT_TRUE(makeCertificates(dir, "hermes-test-ca")) << "openssl failed, see " << dir << "/openssl.log";
  ASSERT_TRUE(makeCertificates(other, "another-ca"));
  BrokerOptions o;
  o.tls_ca_file = dir + "/ca.pem";
  o.tls_cert_file = dir + "/server.pem";
  o.tls_key_file = dir + "/server.key";
  o.require_certificate = true;
  MosquittoBroker broker(::testing::TempDir() + "/mqtt_client_tls", o);
  ASSERT_TRUE(broker.start()) << broker.error();
  MqttParams p = testMqttParams(broker.port());
  p.host = "localhost";  // the name in the server certificate
  p.tls.ca_file = dir + "/ca.pem";
  p.tls.cert_file = dir + "/client.pem";
  p.tls.key_file = dir + "/client.key";
  auto rx = client(p, "hermes-test-tls-rx", {{"t", 2}});
  auto tx = client(p, "hermes-test-tls-tx");
  ASSERT_TRUE(rx && tx);
  ASSERT_TRUE(rx->waitConnected(5)) << rx->lastError() << "\n" << broker.log();
  ASSERT_TRUE(tx->waitConnected(5)) << tx->lastError();
  pumpUntil({rx.get()}, 5, [&] { return rx->stats().subscribed == 1; });
  ASSERT_TRUE(tx->publish("t", {7, 7, 7}, 2));
  ASSERT_TRUE(pumpUntil({rx.get(), tx.get()}, 5, [&] { return rx->stats().received == 1; }));

  MqttParams wrong_ca = p;
  wrong_ca.tls.ca_file = other + "/ca.pem";
  auto bad = client(wrong_ca, "hermes-test-tls-wrong-ca");
  Status s = bad->waitConnected(1);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().find("cannot be reached"), std::string::npos) << s.error();
  std::printf("wrong CA: %s\n", s.error().c_str());

  MqttParams plain = testMqttParams(broker.port());
  auto no_tls = client(plain, "hermes-test-tls-plain");
  EXPECT_FALSE(no_tls->waitConnected(1).ok());

  MqttParams missing = p;
  missing.tls.ca_file = dir + "/nope.pem";
  auto c = MqttClient::create(missing, "hermes-test-tls-missing", {});
  ASSERT_FALSE(c.ok());
  EXPECT_NE(c.error().find("nope.pem"), std::string::npos) << c.error();
}
