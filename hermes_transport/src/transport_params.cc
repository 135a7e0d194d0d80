#include "hermes/transport/transport_params.h"

#include <cctype>
#include <fstream>

#include "hermes/core/keyring.h"

namespace hermes::transport {

Status MqttParams::read(const Config& c) {
  for (Status s : {c.get("mqtt.host", &host), c.get("mqtt.port", &port),
                   c.get("mqtt.keepalive_s", &keepalive_s),
                   c.get("mqtt.client_id_prefix", &client_id_prefix),
                   c.get("mqtt.username", &username), c.get("mqtt.password_file", &password_file),
                   c.get("mqtt.tls.ca_file", &tls.ca_file), c.get("mqtt.tls.cert_file", &tls.cert_file),
                   c.get("mqtt.tls.key_file", &tls.key_file),
                   c.get("mqtt.reconnect_min_s", &reconnect_min_s),
                   c.get("mqtt.reconnect_max_s", &reconnect_max_s),
                   c.get("mqtt.connect_timeout_s", &connect_timeout_s),
                   c.get("mqtt.inbox_capacity", &inbox_capacity)})
    if (!s) return s;
  return validate();
}

Status MqttParams::validate() const {
  if (host.empty()) return Error{"mqtt.host must name the broker"};
  if (port < 1 || port > 65535) return Error{"mqtt.port must be in 1..65535, got " + std::to_string(port)};
  if (keepalive_s < 5 || keepalive_s > 65535)
    return Error{"mqtt.keepalive_s must be in 5..65535 (libmosquitto), got " + std::to_string(keepalive_s)};
  if (client_id_prefix.empty() || client_id_prefix.size() > 32)
    return Error{"mqtt.client_id_prefix must have 1..32 characters"};
  for (char ch : client_id_prefix)
    if (!std::isalnum(static_cast<unsigned char>(ch)) && ch != '-' && ch != '_')
      return Error{"mqtt.client_id_prefix may hold only letters, digits, '-' and '_', got '" +
                   client_id_prefix + "'"};
  if (!password_file.empty() && username.empty())
    return Error{"mqtt.password_file is set but mqtt.username is empty"};
  if (tls.cert_file.empty() != tls.key_file.empty())
    return Error{"mqtt.tls.cert_file and mqtt.tls.key_file go together (client certificate and its key)"};
  if (!tls.cert_file.empty() && tls.ca_file.empty())
    return Error{"mqtt.tls.cert_file needs mqtt.tls.ca_file (TLS is on only with a CA file)"};
  if (!(reconnect_min_s > 0) || !(reconnect_max_s >= reconnect_min_s))
    return Error{"mqtt.reconnect_min_s must be > 0 and <= mqtt.reconnect_max_s"};
  if (!(connect_timeout_s > 0)) return Error{"mqtt.connect_timeout_s must be > 0"};
  if (inbox_capacity < 1) return Error{"mqtt.inbox_capacity must be >= 1"};
  return Status::Ok();
}

void MqttParams::write(ConfigWriter& w) const {
  w.set("mqtt.host", host);
  w.set("mqtt.port", port);
  w.set("mqtt.keepalive_s", keepalive_s);
  w.set("mqtt.client_id_prefix", client_id_prefix);
  w.set("mqtt.username", username);
  w.set("mqtt.password_file", password_file);
  w.set("mqtt.tls.ca_file", tls.ca_file);
  w.set("mqtt.tls.cert_file", tls.cert_file);
  w.set("mqtt.tls.key_file", tls.key_file);
  w.set("mqtt.reconnect_min_s", reconnect_min_s);
  w.set("mqtt.reconnect_max_s", reconnect_max_s);
  w.set("mqtt.connect_timeout_s", connect_timeout_s);
  w.set("mqtt.inbox_capacity", inbox_capacity);
}

std::string MqttParams::broker() const { return host + ":" + std::to_string(port); }

Expected<std::string> MqttParams::readPassword() const {
  if (password_file.empty()) return std::string();
  const std::string path = expandHome(password_file);
  std::ifstream in(path);
  if (!in) return Error{"mqtt.password_file " + path + " cannot be read"};
  std::string line;
  std::getline(in, line);
  if (!line.empty() && line.back() == '\r') line.pop_back();
  if (line.empty()) return Error{"mqtt.password_file " + path + ": the first line (the password) is empty"};
  return line;
}

Status TransportParams::read(const Config& c) {
  if (Status s = c.getChoice("transport", {"ros", "mqtt"}, &kind); !s) return s;
  if (Status s = mqtt.read(c); !s) return s;
  return validate();
}

Status TransportParams::validate() const {
  if (kind != "ros" && kind != "mqtt") return Error{"transport must be ros or mqtt, got '" + kind + "'"};
  return mqtt.validate();
}

void TransportParams::write(ConfigWriter& w) const {
  w.set("transport", kind);
  mqtt.write(w);
}

}  // namespace hermes::transport
