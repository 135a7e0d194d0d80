// How submaps, acknowledgements and heartbeats travel between the agent nodelets
// and the server node: ROS topics (default) or MQTT through a broker (keys
// `transport` and `mqtt.*` of config/hermes.yaml). Images, odometry and the rviz
// outputs stay on ROS either way; the offline runner always uses its emulated link.
#pragma once

#include <string>

#include "hermes/core/config.h"
#include "hermes/core/status.h"

namespace hermes::transport {

/// TLS towards the broker: on when `ca_file` is set.
struct MqttTlsParams {
  std::string ca_file;    ///< PEM CA certificate(s) that signed the broker's certificate
  std::string cert_file;  ///< client certificate (PEM), with key_file; empty = none
  std::string key_file;   ///< client private key (PEM, unencrypted)
  bool enabled() const { return !ca_file.empty(); }
};

struct MqttParams {
  std::string host = "127.0.0.1";  ///< broker host name or address
  int port = 1883;                 ///< broker port (8883 is the usual TLS port)
  int keepalive_s = 10;            ///< [s] MQTT keepalive: a silent broker is noticed after ~1.5x
  /// Client ids are "<prefix>-agent-<robot>" and "<prefix>-server"; stable, so the
  /// broker keeps each one's session (subscriptions, queued QoS 2 messages) while
  /// it is away.
  std::string client_id_prefix = "hermes";
  std::string username;       ///< empty = anonymous
  std::string password_file;  ///< first line = the password; "~/" = $HOME; needs username
  MqttTlsParams tls;
  double reconnect_min_s = 0.5;     ///< [s] first wait after a failed or lost connection
  double reconnect_max_s = 30;      ///< [s] the wait doubles up to this
  double connect_timeout_s = 5;     ///< [s] a connection attempt without CONNACK is given up
  int inbox_capacity = 1000;        ///< received messages waiting to be handled (drop policy: mqtt_client.h)

  Status read(const Config& c);
  Status validate() const;
  void write(ConfigWriter& w) const;
  /// "host:port" (for messages).
  std::string broker() const;
  /// The password from password_file (empty without one); errors name the file.
  Expected<std::string> readPassword() const;
};

struct TransportParams {
  std::string kind = "ros";  ///< key `transport`: ros | mqtt
  MqttParams mqtt;           ///< section mqtt (read and checked whatever the kind)

  bool mqttEnabled() const { return kind == "mqtt"; }
  Status read(const Config& c);
  Status validate() const;
  void write(ConfigWriter& w) const;
};

}  // namespace hermes::transport
