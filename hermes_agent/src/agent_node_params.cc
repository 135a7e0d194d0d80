#include "agent_node_params.h"

namespace hermes_agent {
namespace {

template <typename T>
std::optional<T> optionalParam(const ros::NodeHandle& pnh, const std::string& name) {
  T value;
  if (pnh.getParam(name, value)) return value;
  return std::nullopt;
}

}  // namespace

AgentNodeParams AgentNodeParams::read(const ros::NodeHandle& nh, const ros::NodeHandle& pnh) {
  AgentNodeParams p;
  std::string ns = nh.getNamespace();
  while (!ns.empty() && ns.front() == '/') ns.erase(0, 1);
  pnh.param("robot", p.robot, ns.empty() ? std::string("agent") : ns);
  p.config_file = std::string(HERMES_SOURCE_DIR) + "/config/hermes.yaml";
  pnh.param("mode", p.mode, p.mode);
  pnh.param("config", p.config_file, p.config_file);
  pnh.param("dataset", p.dataset, p.dataset);
  pnh.param("camera", p.camera, p.camera);
  pnh.param("queue_size", p.queue_size, p.queue_size);
  if (pnh.hasParam("rectified")) {  // true/false arrive as bools from roslaunch
    bool b = false;
    if (pnh.getParam("rectified", b)) p.rectified = b ? "true" : "false";
    else pnh.getParam("rectified", p.rectified);
  }
  pnh.param("parallel", p.parallel, p.parallel);
  p.timing_window = optionalParam<int>(pnh, "timing_window");
  p.spool_dir = optionalParam<std::string>(pnh, "spool_dir");
  pnh.param("clear_spool", p.clear_spool, p.clear_spool);
  p.auth = optionalParam<bool>(pnh, "auth");
  pnh.param("key_file", p.key_file, p.key_file);
  pnh.param("transport", p.transport, p.transport);
  p.mqtt_host = optionalParam<std::string>(pnh, "mqtt_host");
  p.mqtt_port = optionalParam<int>(pnh, "mqtt_port");
  pnh.param("relay_via", p.relay_via, p.relay_via);
  pnh.param("relay_for", p.relay_for, p.relay_for);
  p.relay_spool_dir = optionalParam<std::string>(pnh, "relay_spool_dir");
  return p;
}

hermes::Status AgentNodeParams::validate() const {
  if (!mode.empty() && mode != "stereo" && mode != "rgbd")
    return hermes::Error{"~mode must be stereo or rgbd, got '" + mode + "'"};
  if (rectified != "auto" && rectified != "true" && rectified != "false")
    return hermes::Error{"~rectified must be auto, true or false, got '" + rectified + "'"};
  if (queue_size < 1) return hermes::Error{"~queue_size must be >= 1, got " + std::to_string(queue_size)};
  return hermes::Status::Ok();
}

}  // namespace hermes_agent
