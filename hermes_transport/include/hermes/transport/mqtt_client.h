// One MQTT connection over libmosquitto (RAII owner of the handle): MQTT 3.1.1,
// persistent session (clean_session false, a stable client id), optional TLS and
// username/password, reconnect with backoff (reconnect_backoff.h), and the
// subscriptions renewed on every connection (a broker that lost our session
// also lost them).
//
// Threads: either the owner calls pump() (synchronous mode: deterministic tests)
// or start() runs pump() on the client's own network thread. libmosquitto's
// callbacks run inside pump(); they only fill the inbox, which the owner empties
// with drain() from its own thread. publish() may be called from any thread.
//
// Inbox: at most MqttParams::inbox_capacity received messages wait; when it is
// full a newly received message is dropped and counted (stats().dropped) --
// safe for Hermes because nothing is acknowledged until its handler ran: a
// dropped submap is resent from the robot's spool, a dropped ack makes the robot
// resend a submap the server then acknowledges again. Connection events are
// always queued.
//
// publish() while offline is refused (returns an error): libmosquitto would
// queue it in memory without bound, and the robot's spool resends anyway.
#pragma once

#include <atomic>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "hermes/core/status.h"
#include "hermes/transport/reconnect_backoff.h"
#include "hermes/transport/transport_params.h"

struct mosquitto;
struct mosquitto_message;

namespace hermes::transport {

struct MqttSubscription {
  std::string pattern;  ///< topic filter ('+' and '#' allowed)
  int qos = 2;
};

struct MqttEvent {
  enum class Kind {
    kConnected,       ///< CONNACK accepted; `session_present`: the broker still had our session
    kConnectionLost,  ///< an established connection went away (`text` says why)
    kMessage,         ///< a message on `topic`
  };
  Kind kind = Kind::kMessage;
  bool session_present = false;
  std::string topic;
  std::vector<std::uint8_t> payload;
  std::string text;
};

struct MqttClientStats {
  std::size_t connects = 0;         ///< accepted CONNACKs
  std::size_t sessions_resumed = 0; ///< ... of which the broker still had our session
  std::size_t losses = 0;           ///< established connections lost
  std::size_t failed_attempts = 0;  ///< attempts that did not end in a connection
  std::size_t subscribed = 0;       ///< SUBACKs (one per subscription per connection)
  std::size_t published = 0;        ///< messages handed to libmosquitto
  std::size_t completed = 0;        ///< ... whose QoS handshake finished (PUBACK / PUBCOMP)
  std::size_t refused = 0;          ///< publish() calls refused (offline or an error)
  std::size_t received = 0;         ///< messages received (dropped ones included)
  std::size_t dropped = 0;          ///< received while the inbox was full
};

class MqttClient {
 public:
  /// Checks the parameters, reads the password file, sets TLS up; does not connect.
  static Expected<std::unique_ptr<MqttClient>> create(const MqttParams& params,
                                                      const std::string& client_id,
                                                      std::vector<MqttSubscription> subscriptions);
  ~MqttClient();  ///< stops the thread, disconnects cleanly (the session stays on the broker)
  MqttClient(const MqttClient&) = delete;
  MqttClient& operator=(const MqttClient&) = delete;

  /// Synchronous mode: one step -- a connection attempt when one is due, then up
  /// to `timeout_ms` of network traffic. Not while the network thread runs.
  void pump(int timeout_ms);
  /// Threaded mode: pump() on the client's own thread until stop() / destruction.
  void start();
  void stop();

  /// Waits up to `timeout_s` for a connection (pumping in synchronous mode). The
  /// error names the broker and why it could not be reached; the client keeps
  /// trying afterwards either way.
  Status waitConnected(double timeout_s);

  /// Publishes (never retained). Errors: offline, or libmosquitto's refusal.
  Status publish(const std::string& topic, const std::vector<std::uint8_t>& payload, int qos);
  /// Takes everything received since the last call, in arrival order.
  std::vector<MqttEvent> drain();

  bool connected() const { return phase_ == Phase::kConnected; }
  const std::string& clientId() const { return client_id_; }
  const std::string& broker() const { return broker_; }
  /// Why the last attempt failed or the last connection was lost ("" if never).
  std::string lastError() const;
  MqttClientStats stats() const;

 private:
  enum class Phase { kOffline, kConnecting, kConnected };
  MqttClient(const MqttParams& params, std::string client_id, std::vector<MqttSubscription> subs);
  Status setUp(const std::string& password);
  void attempt(double now);
  void wentOffline(const std::string& why, double now);
  void push(MqttEvent event);

  static void onConnect(mosquitto* m, void* self, int rc, int flags);
  static void onDisconnect(mosquitto* m, void* self, int rc);
  static void onMessage(mosquitto* m, void* self, const mosquitto_message* msg);
  static void onPublish(mosquitto* m, void* self, int mid);
  static void onSubscribe(mosquitto* m, void* self, int mid, int qos_count, const int* granted);

  MqttParams params_;
  std::string client_id_, broker_;
  std::vector<MqttSubscription> subscriptions_;
  mosquitto* mosq_ = nullptr;
  std::atomic<Phase> phase_{Phase::kOffline};
  bool ever_tried_ = false;     ///< pump thread only
  double attempt_started_ = 0;  ///< pump thread only
  ReconnectBackoff backoff_;    ///< pump thread only

  mutable std::mutex mu_;  ///< inbox_, stats_, last_error_
  std::deque<MqttEvent> inbox_;
  std::size_t inbox_messages_ = 0;
  MqttClientStats stats_;
  std::string last_error_;

  std::atomic<bool> running_{false};
  std::thread thread_;
};

/// Seconds of a monotonic clock (the client's backoff and timeouts).
double mqttClock();

}  // namespace hermes::transport
