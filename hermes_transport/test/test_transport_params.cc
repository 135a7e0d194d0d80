#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "hermes/transport/reconnect_backoff.h"
#include "hermes/transport/transport_params.h"

using namespace hermes;
using namespace hermes::transport;

TEST(TransportParams, DefaultsAreRosAndValid) {
  TransportParams p;
  EXPECT_TRUE(p.validate());
  EXPECT_FALSE(p.mqttEnabled());
  EXPECT_EQ(p.mqtt.broker(), "127.0.0.1:1883");
  EXPECT_FALSE(p.mqtt.tls.enabled());
}

TEST(TransportParams, ReadWriteRoundTrip) {
  auto c = Config::fromString(
      "transport: mqtt\nmqtt:\n  host: broker.lan\n  port: 8883\n  keepalive_s: 20\n"
      "  client_id_prefix: site-a\n  username: robots\n  password_file: /tmp/pw\n"
      "  tls:\n    ca_file: /etc/ca.pem\n    cert_file: c.pem\n    key_file: k.pem\n"
      "  reconnect_min_s: 1\n  reconnect_max_s: 60\n  connect_timeout_s: 3\n  inbox_capacity: 50\n",
      "test");
  ASSERT_TRUE(c.ok()) << c.error();
  TransportParams p;
  ASSERT_TRUE(p.read(*c));
  EXPECT_TRUE(p.mqttEnabled());
  EXPECT_EQ(p.mqtt.broker(), "broker.lan:8883");
  EXPECT_TRUE(p.mqtt.tls.enabled());
  EXPECT_EQ(p.mqtt.inbox_capacity, 50);
  EXPECT_TRUE(c->unusedKeys().empty());
  ConfigWriter w;
  p.write(w);
  auto again = Config::fromString(w.yaml(), "written");
  ASSERT_TRUE(again.ok()) << again.error();
  TransportParams q;
  ASSERT_TRUE(q.read(*again));
  ConfigWriter w2;
  q.write(w2);
  EXPECT_EQ(w.yaml(), w2.yaml());
}

TEST(TransportParams, BadValuesNameTheKey) {
  auto check = [](const std::string& yaml, const std::string& key) {
    auto c = Config::fromString(yaml, "test");
    ASSERT_TRUE(c.ok()) << c.error();
    TransportParams p;
    Status s = p.read(*c);
    ASSERT_FALSE(s.ok()) << yaml;
    EXPECT_NE(s.error().find(key), std::string::npos) << s.error();
  };
  check("transport: zmq\n", "transport");
  check("mqtt:\n  port: 0\n", "mqtt.port");
  check("mqtt:\n  host: ''\n", "mqtt.host");
  check("mqtt:\n  keepalive_s: 1\n", "mqtt.keepalive_s");
  check("mqtt:\n  client_id_prefix: 'a/b'\n", "mqtt.client_id_prefix");
  check("mqtt:\n  password_file: /tmp/x\n", "mqtt.password_file");
  check("mqtt:\n  tls:\n    cert_file: c.pem\n", "mqtt.tls.cert_file");
  check("mqtt:\n  tls:\n    cert_file: c.pem\n    key_file: k.pem\n", "mqtt.tls.cert_file");
  check("mqtt:\n  reconnect_min_s: 5\n  reconnect_max_s: 1\n", "mqtt.reconnect_min_s");
  check("mqtt:\n  inbox_capacity: 0\n", "mqtt.inbox_capacity");
  check("mqtt:\n  port: eighty\n", "mqtt.port");
}

TEST(TransportParams, PasswordFile) {
  const std::string path = ::testing::TempDir() + "/mqtt_pw";
  MqttParams p;
  p.username = "robots";
  EXPECT_EQ(*p.readPassword(), "");
  p.password_file = path;
  std::filesystem::remove(path);
  auto r = p.readPassword();
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().find(path), std::string::npos) << r.error();
  std::ofstream(path) << "s3cret\r\nignored\n";
  r = p.readPassword();
  ASSERT_TRUE(r.ok()) << r.error();
  EXPECT_EQ(*r, "s3cret");
  std::ofstream(path) << "\n";
  EXPECT_FALSE(p.readPassword().ok());
}

TEST(ReconnectBackoff, DoublesUpToTheCapAndStartsOver) {
  ReconnectBackoff b(0.5, 4.0);
  EXPECT_TRUE(b.mayTry(0));
  EXPECT_DOUBLE_EQ(b.failed(10), 10.5);
  EXPECT_FALSE(b.mayTry(10.4));
  EXPECT_TRUE(b.mayTry(10.5));
  EXPECT_DOUBLE_EQ(b.failed(11), 12.0);
  EXPECT_DOUBLE_EQ(b.failed(12), 14.0);
  EXPECT_DOUBLE_EQ(b.failed(14), 18.0);
  EXPECT_DOUBLE_EQ(b.failed(18), 22.0);  // capped at 4 s
  for (int i = 0; i < 40; ++i) b.failed(100);
  EXPECT_DOUBLE_EQ(b.nextAttempt(), 104.0);
  b.succeeded();
  EXPECT_EQ(b.failures(), 0u);
  EXPECT_TRUE(b.mayTry(0));
  EXPECT_DOUBLE_EQ(b.failed(200), 200.5);
}
