// A real Debian `mosquitto` broker for tests: its own folder with a generated
// minimal config (one listener on 127.0.0.1 and a free port), started as a child
// process, killed with SIGKILL (a crash: nothing flushed) and started again on
// the same port.
#pragma once

#include <sys/types.h>

#include <filesystem>
#include <string>

#include "hermes/transport/transport_params.h"

/// Skips the test (with the reason) when there is no mosquitto binary.
#define HERMES_REQUIRE_MOSQUITTO()                                                   \
  if (::hermes::transport::test::MosquittoBroker::binary().empty())                  \
  GTEST_SKIP() << "no mosquitto binary (apt-get install mosquitto, or set HERMES_MOSQUITTO)"

namespace hermes::transport::test {

/// Client parameters for a test broker on `port`: short keepalive and backoff.
MqttParams testMqttParams(int port);

struct BrokerOptions {
  bool persistence = false;   ///< true: sessions survive a restart (persistence file in the folder)
  std::string password_file;  ///< set: allow_anonymous false, users from this mosquitto_passwd file
  /// Set: the listener speaks TLS with this CA, certificate and key (PEM files);
  /// with require_certificate, clients need a certificate signed by the CA.
  std::string tls_ca_file, tls_cert_file, tls_key_file;
  bool require_certificate = false;
};

class MosquittoBroker {
 public:
  /// The broker binary: $HERMES_MOSQUITTO, else `mosquitto` on PATH, else
  /// /usr/sbin/mosquitto; empty when there is none (tests then skip).
  static std::string binary();
  /// A TCP port on 127.0.0.1 nobody listens on right now.
  static int freePort();

  /// `port` 0: a free one (freePort()).
  MosquittoBroker(std::string dir, BrokerOptions options = {}, int port = 0);
  ~MosquittoBroker();
  MosquittoBroker(const MosquittoBroker&) = delete;
  MosquittoBroker& operator=(const MosquittoBroker&) = delete;

  /// Starts the broker and waits until it accepts connections; false (and
  /// error()) when it does not within 5 s.
  bool start();
  /// SIGKILL and reap.
  void kill();
  /// With persistence: waits up to `timeout_s` until the broker has written its
  /// database after `since` (its autosave runs every second); false if it did not.
  bool waitSaved(std::filesystem::file_time_type since, double timeout_s) const;
  bool running() const { return pid_ > 0; }
  int port() const { return port_; }
  const std::string& error() const { return error_; }
  /// The broker's log (for failure messages).
  std::string log() const;

 private:
  std::string dir_;
  BrokerOptions options_;
  int port_ = 0;
  pid_t pid_ = -1;
  std::string error_;
};

}  // namespace hermes::transport::test
