// The Agent nodelet's private parameters (agent_nodelet.cc lists what each
// means), read in one place. Those left unset keep what the config file says.
#pragma once

#include <optional>
#include <string>

#include <ros/node_handle.h>

#include "hermes/core/status.h"

namespace hermes_agent {

struct AgentNodeParams {
  std::string robot;        ///< ~robot; default the namespace, else "agent"
  std::string mode;         ///< ~mode: "" (the calibration's kind), stereo or rgbd
  std::string config_file;  ///< ~config; default <source>/config/hermes.yaml
  std::string dataset;      ///< ~dataset: the camera and body<-camera from a dataset folder
  std::string camera;       ///< ~camera: a config/cameras name or calibration file / folder
  std::string rectified = "auto";  ///< ~rectified: auto | true | false
  int queue_size = 30;      ///< ~queue_size per image topic
  bool parallel = true;     ///< ~parallel: worker threads (tracking never waits)
  std::optional<int> timing_window;       ///< ~timing_window; default agent.timing_window or 3000
  std::optional<std::string> spool_dir;   ///< ~spool_dir; default /tmp/hermes_spool/<robot>
  bool clear_spool = false;               ///< ~clear_spool
  std::optional<bool> auth;               ///< ~auth; default uplink.auth.enabled
  std::string key_file;                   ///< ~key_file; "" = uplink.auth.key_file
  std::string transport;                  ///< ~transport; "" = the config's
  std::optional<std::string> mqtt_host;   ///< ~mqtt_host
  std::optional<int> mqtt_port;           ///< ~mqtt_port
  std::string relay_via;                  ///< ~relay_via
  std::string relay_for;                  ///< ~relay_for "U1,U2"
  std::optional<std::string> relay_spool_dir;  ///< ~relay_spool_dir; default <spool_dir>.relay

  /// Every private parameter of the nodelet (nh: its namespace, the default robot name).
  static AgentNodeParams read(const ros::NodeHandle& nh, const ros::NodeHandle& pnh);
  /// The checks that need no config file: mode, rectified, queue_size.
  hermes::Status validate() const;
};

}  // namespace hermes_agent
