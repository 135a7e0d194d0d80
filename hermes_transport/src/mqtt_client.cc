#include "hermes/transport/mqtt_client.h"

#include <mosquitto.h>

#include <cerrno>
#include <cstdio>
#include <chrono>
#include <cstring>
#include <filesystem>

namespace hermes::transport {
namespace {

std::once_flag g_lib_init;

/// libmosquitto's text for `rc` (with errno's for MOSQ_ERR_ERRNO).
std::string describe(int rc, int err) {
  if (rc == MOSQ_ERR_ERRNO) return std::strerror(err);
  return mosquitto_strerror(rc);
}

/// "0.5", "30", "1.25" (seconds in messages).
std::string seconds(double s) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", s);
  return buf;
}

void sleepFor(double seconds) {
  if (seconds > 0) std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
}

}  // namespace

double mqttClock() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

MqttClient::MqttClient(const MqttParams& params, std::string client_id, std::vector<MqttSubscription> subs)
    : params_(params),
      client_id_(std::move(client_id)),
      broker_(params.broker()),
      subscriptions_(std::move(subs)),
      backoff_(params.reconnect_min_s, params.reconnect_max_s) {}

Expected<std::unique_ptr<MqttClient>> MqttClient::create(const MqttParams& params,
                                                         const std::string& client_id,
                                                         std::vector<MqttSubscription> subscriptions) {
  if (Status s = params.validate(); !s) return Error{s.error()};
  if (client_id.empty() || client_id.size() > 128)
    return Error{"mqtt: client id '" + client_id + "' must have 1..128 characters"};
  for (const MqttSubscription& sub : subscriptions)
    if (sub.pattern.empty() || sub.qos < 0 || sub.qos > 2)
      return Error{"mqtt: bad subscription '" + sub.pattern + "' (qos " + std::to_string(sub.qos) + ")"};
  auto password = params.readPassword();
  if (!password) return Error{password.error()};
  std::call_once(g_lib_init, [] { mosquitto_lib_init(); });
  std::unique_ptr<MqttClient> c(new MqttClient(params, client_id, std::move(subscriptions)));
  if (Status s = c->setUp(*password); !s) return Error{s.error()};
  return c;
}

Status MqttClient::setUp(const std::string& password) {
  // clean_session = false: the broker keeps our subscriptions and the QoS 1/2
  // messages for us while we are away (a persistent session).
  mosq_ = mosquitto_new(client_id_.c_str(), false, this);
  if (!mosq_) return Error{"mqtt: mosquitto_new failed for client " + client_id_ + ": " + std::strerror(errno)};
  mosquitto_connect_with_flags_callback_set(mosq_, &MqttClient::onConnect);
  mosquitto_disconnect_callback_set(mosq_, &MqttClient::onDisconnect);
  mosquitto_message_callback_set(mosq_, &MqttClient::onMessage);
  mosquitto_publish_callback_set(mosq_, &MqttClient::onPublish);
  mosquitto_subscribe_callback_set(mosq_, &MqttClient::onSubscribe);
  mosquitto_int_option(mosq_, MOSQ_OPT_TCP_NODELAY, 1);
  if (!params_.username.empty()) {
    const int rc = mosquitto_username_pw_set(mosq_, params_.username.c_str(),
                                             password.empty() ? nullptr : password.c_str());
    if (rc != MOSQ_ERR_SUCCESS) return Error{"mqtt.username: " + describe(rc, errno)};
  }
  if (params_.tls.enabled()) {
    for (const std::string* f : {&params_.tls.ca_file, &params_.tls.cert_file, &params_.tls.key_file})
      if (!f->empty() && !std::filesystem::is_regular_file(*f))
        return Error{"mqtt.tls: " + *f + " is not a readable file"};
    const int rc = mosquitto_tls_set(mosq_, params_.tls.ca_file.c_str(), nullptr,
                                     params_.tls.cert_file.empty() ? nullptr : params_.tls.cert_file.c_str(),
                                     params_.tls.key_file.empty() ? nullptr : params_.tls.key_file.c_str(),
                                     nullptr);
    if (rc != MOSQ_ERR_SUCCESS)
      return Error{"mqtt.tls (ca " + params_.tls.ca_file + "): " + describe(rc, errno)};
  }
  return Status::Ok();
}

MqttClient::~MqttClient() {
  stop();
  if (!mosq_) return;
  if (phase_ == Phase::kConnected) {
    mosquitto_disconnect(mosq_);  // a clean DISCONNECT; the persistent session stays
    mosquitto_loop(mosq_, 50, 1);
  }
  mosquitto_destroy(mosq_);
}

void MqttClient::start() {
  if (running_.exchange(true)) return;
  mosquitto_threaded_set(mosq_, true);
  thread_ = std::thread([this] {
    while (running_) pump(100);
  });
}

void MqttClient::stop() {
  if (!running_.exchange(false)) return;
  if (thread_.joinable()) thread_.join();
}

void MqttClient::attempt(double now) {
  const int rc = ever_tried_ ? mosquitto_reconnect_async(mosq_)
                             : mosquitto_connect_async(mosq_, params_.host.c_str(), params_.port,
                                                       params_.keepalive_s);
  const int err = errno;
  ever_tried_ = true;
  attempt_started_ = now;
  if (rc != MOSQ_ERR_SUCCESS) {
    wentOffline(describe(rc, err), now);
    return;
  }
  phase_ = Phase::kConnecting;
}

void MqttClient::wentOffline(const std::string& why, double now) {
  const Phase was = phase_.exchange(Phase::kOffline);
  backoff_.failed(now);
  std::lock_guard<std::mutex> lock(mu_);
  last_error_ = why;
  if (was == Phase::kConnected) {
    ++stats_.losses;
    MqttEvent e;
    e.kind = MqttEvent::Kind::kConnectionLost;
    e.text = why;
    inbox_.push_back(std::move(e));
  } else {
    ++stats_.failed_attempts;
  }
}

void MqttClient::pump(int timeout_ms) {
  const double now = mqttClock();
  if (phase_ == Phase::kOffline) {
    if (!backoff_.mayTry(now)) {
      sleepFor(std::min(timeout_ms / 1000.0, backoff_.nextAttempt() - now));
      return;
    }
    attempt(now);
    if (phase_ == Phase::kOffline) return;
  }
  const int rc = mosquitto_loop(mosq_, timeout_ms, 1);
  const int err = errno;
  if (rc != MOSQ_ERR_SUCCESS) {
    if (phase_ != Phase::kOffline) wentOffline(describe(rc, err), mqttClock());
    return;
  }
  if (phase_ == Phase::kConnecting && mqttClock() - attempt_started_ > params_.connect_timeout_s) {
    wentOffline("no CONNACK within mqtt.connect_timeout_s = " + seconds(params_.connect_timeout_s) + " s",
                mqttClock());
    mosquitto_disconnect(mosq_);
  }
}

Status MqttClient::waitConnected(double timeout_s) {
  const double deadline = mqttClock() + timeout_s;
  while (!connected() && mqttClock() < deadline) {
    if (running_) sleepFor(0.01);
    else pump(20);
  }
  if (connected()) return Status::Ok();
  const MqttClientStats st = stats();
  return Error{"MQTT broker " + broker_ + " cannot be reached by client " + client_id_ + ": " +
               (lastError().empty() ? std::string("no answer") : lastError()) + " (" +
               std::to_string(st.failed_attempts) + " failed attempts in " + seconds(timeout_s) +
               " s; still trying, waiting up to mqtt.reconnect_max_s = " + seconds(params_.reconnect_max_s) +
               " s between attempts)"};
}

Status MqttClient::publish(const std::string& topic, const std::vector<std::uint8_t>& payload, int qos) {
  constexpr std::size_t kMaxPayload = 268435455;  // MQTT's remaining-length limit, less the header
  if (payload.size() > kMaxPayload - topic.size() - 4) {
    std::lock_guard<std::mutex> lock(mu_);
    ++stats_.refused;
    return Error{"mqtt: payload of " + std::to_string(payload.size()) + " bytes on " + topic +
                 " exceeds the MQTT packet limit (256 MB)"};
  }
  if (phase_ != Phase::kConnected) {
    std::lock_guard<std::mutex> lock(mu_);
    ++stats_.refused;
    return Error{"mqtt: not connected to " + broker_ + " (" +
                 (last_error_.empty() ? std::string("connecting") : last_error_) + ")"};
  }
  const int rc = mosquitto_publish(mosq_, nullptr, topic.c_str(), static_cast<int>(payload.size()),
                                   payload.data(), qos, false);
  const int err = errno;
  std::lock_guard<std::mutex> lock(mu_);
  if (rc != MOSQ_ERR_SUCCESS) {
    ++stats_.refused;
    return Error{"mqtt: publish on " + topic + " refused: " + describe(rc, err)};
  }
  ++stats_.published;
  return Status::Ok();
}

std::vector<MqttEvent> MqttClient::drain() {
  std::lock_guard<std::mutex> lock(mu_);
  std::vector<MqttEvent> out(std::make_move_iterator(inbox_.begin()), std::make_move_iterator(inbox_.end()));
  inbox_.clear();
  inbox_messages_ = 0;
  return out;
}

std::string MqttClient::lastError() const {
  std::lock_guard<std::mutex> lock(mu_);
  return last_error_;
}

MqttClientStats MqttClient::stats() const {
  std::lock_guard<std::mutex> lock(mu_);
  return stats_;
}

void MqttClient::onConnect(mosquitto* m, void* self, int rc, int flags) {
  auto* c = static_cast<MqttClient*>(self);
  if (rc != 0) {  // refused by the broker (credentials, protocol, ...): libmosquitto closes the socket
    c->wentOffline(std::string("broker refused the connection: ") + mosquitto_connack_string(rc), mqttClock());
    return;
  }
  c->phase_ = Phase::kConnected;
  c->backoff_.succeeded();
  for (const MqttSubscription& sub : c->subscriptions_)
    mosquitto_subscribe(m, nullptr, sub.pattern.c_str(), sub.qos);
  MqttEvent e;
  e.kind = MqttEvent::Kind::kConnected;
  e.session_present = (flags & 1) != 0;
  std::lock_guard<std::mutex> lock(c->mu_);
  ++c->stats_.connects;
  if (e.session_present) ++c->stats_.sessions_resumed;
  c->inbox_.push_back(std::move(e));
}

void MqttClient::onDisconnect(mosquitto*, void* self, int rc) {
  auto* c = static_cast<MqttClient*>(self);
  if (rc == 0) {  // our own DISCONNECT
    c->phase_ = Phase::kOffline;
    return;
  }
  if (c->phase_ != Phase::kOffline) c->wentOffline(describe(rc, errno), mqttClock());
}

void MqttClient::onMessage(mosquitto*, void* self, const mosquitto_message* msg) {
  auto* c = static_cast<MqttClient*>(self);
  std::lock_guard<std::mutex> lock(c->mu_);
  ++c->stats_.received;
  if (c->inbox_messages_ >= static_cast<std::size_t>(c->params_.inbox_capacity)) {
    ++c->stats_.dropped;
    return;
  }
  MqttEvent e;
  e.kind = MqttEvent::Kind::kMessage;
  e.topic = msg->topic ? msg->topic : "";
  const auto* p = static_cast<const std::uint8_t*>(msg->payload);
  if (p && msg->payloadlen > 0) e.payload.assign(p, p + msg->payloadlen);
  c->inbox_.push_back(std::move(e));
  ++c->inbox_messages_;
}

void MqttClient::onPublish(mosquitto*, void* self, int) {
  auto* c = static_cast<MqttClient*>(self);
  std::lock_guard<std::mutex> lock(c->mu_);
  ++c->stats_.completed;
}

void MqttClient::onSubscribe(mosquitto*, void* self, int, int, const int*) {
  auto* c = static_cast<MqttClient*>(self);
  std::lock_guard<std::mutex> lock(c->mu_);
  ++c->stats_.subscribed;
}

}  // namespace hermes::transport
