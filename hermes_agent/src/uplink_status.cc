#include "uplink_status.h"

#include <unistd.h>

namespace hermes_agent {
namespace {

nlohmann::json keysJson(const UplinkStatusContext::Keys& k) {
  nlohmann::json a = nlohmann::json::array();
  for (const auto& [session, seq] : k) a.push_back({session, seq});
  return a;
}

nlohmann::json mqttJson(hermes::transport::MqttAgentLink& link) {
  const hermes::transport::MqttClientStats m = link.client().stats();
  return {{"broker", link.client().broker()}, {"connected", link.client().connected()},
          {"connects", m.connects}, {"sessions_resumed", m.sessions_resumed},
          {"losses", m.losses}, {"failed_attempts", m.failed_attempts},
          {"published", m.published}, {"refused", m.refused}, {"received", m.received},
          {"dropped", m.dropped}, {"malformed", link.malformed()},
          {"last_error", link.client().lastError()}};
}

}  // namespace

nlohmann::json uplinkStatusJson(const hermes::agent::AgentPipeline& pipeline, const UplinkStatusContext& c) {
  const hermes::agent::WindowCounters w = pipeline.windows();
  nlohmann::json j;
  j["robot"] = c.robot;
  j["uuid"] = c.uuid;
  j["pid"] = static_cast<std::int64_t>(::getpid());  // tells restarted processes apart
  j["session"] = pipeline.session();
  j["created"] = c.created ? keysJson(*c.created) : nlohmann::json::array();
  j["replayed"] = c.replayed ? keysJson(*c.replayed) : nlohmann::json::array();
  j["windows"] = {{"total", w.windows}, {"submitted", w.sent}, {"deferred", w.deferred},
                  {"failed", w.failed}, {"refused", w.refused},
                  {"extended_keyframes", w.extended_keyframes}};
  pipeline.withUplink([&](const hermes::agent::UplinkSender* up) {  // the uplink thread shares it
    j["pending"] = keysJson(up->buffer().pendingKeys());
    j["sends"] = up->stats().sends;
    j["resends"] = up->stats().resends;
    j["acked"] = up->stats().acked;
    j["spool_pending_bytes"] = up->buffer().pendingBytes();
    j["spool_file_bytes"] = up->buffer().fileBytes();
  });
  j["spool_cap_bytes"] = c.spool_cap_bytes;
  const hermes::agent::AgentThreadStats t = pipeline.threadStats();
  j["threads"] = {{"parallel", t.parallel},
                  {"ba_jobs", t.mapping.ba_jobs},
                  {"keyframes_merged", t.mapping.merged},
                  {"keyframes_skipped", t.mapping.skipped},
                  {"max_keyframes_waiting", t.mapping.max_waiting},
                  {"windows_queued", t.windows.pushed},
                  {"windows_merged", t.windows.merged},
                  {"window_queue_high_water", t.windows.high_water}};
  nlohmann::json timings = nlohmann::json::object();  // [ms] per stage, last timing_window samples
  for (const auto& [stage, st] : pipeline.timings().summary())
    timings[stage] = {{"median", st.median}, {"p95", st.p95}, {"count", st.count}};
  j["timings_ms"] = timings;
  j["done"] = c.done;
  j["transport"] = c.mqtt ? "mqtt" : "ros";
  if (!c.relay_via.empty()) {
    j["relay_via"] = c.relay_via;
    j["hop_acks"] = c.hop_acks;
    j["handed_over"] = pipeline.withUplink(
        [](const hermes::agent::UplinkSender* up) { return up ? up->handedOverCount() : 0; });
  }
  if (c.relay) j["relay_for"] = c.relay->status();  // per relayed robot
  if (c.mqtt) j["mqtt"] = mqttJson(*c.mqtt);
  j["frames"] = c.frames;
  return j;
}

}  // namespace hermes_agent
