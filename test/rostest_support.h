// Helpers of the rostests: what the ROS master knows of the running nodes, and
// the server's closing status.
#pragma once

#include <gtest/gtest.h>
#include <ros/master.h>
#include <ros/network.h>
#include <ros/ros.h>
#include <xmlrpcpp/XmlRpc.h>

#include <set>
#include <string>

#include <nlohmann/json.hpp>

namespace hermes_tests {

/// Process id of a node, asked through the master and the node's XML-RPC API; 0 if unknown.
inline int nodePid(const std::string& node) {
  XmlRpc::XmlRpcValue args, result, payload;
  args[0] = ros::this_node::getName();
  args[1] = node;
  if (!ros::master::execute("lookupNode", args, result, payload, false)) return 0;
  std::string host;
  std::uint32_t port = 0;
  if (!ros::network::splitURI(static_cast<std::string>(payload), host, port)) return 0;
  XmlRpc::XmlRpcClient client(host.c_str(), static_cast<int>(port), "/");
  XmlRpc::XmlRpcValue pid_args, pid_result;
  pid_args[0] = ros::this_node::getName();
  if (!client.execute("getPid", pid_args, pid_result) || pid_result.getType() != XmlRpc::XmlRpcValue::TypeArray ||
      pid_result.size() < 3 || pid_result[2].getType() != XmlRpc::XmlRpcValue::TypeInt)
    return 0;
  return static_cast<int>(pid_result[2]);
}

/// Nodes publishing (`publishers`) or subscribing `topic`, from the master's system state.
inline std::set<std::string> nodesOf(const std::string& topic, bool publishers) {
  XmlRpc::XmlRpcValue args, result, payload;
  args[0] = ros::this_node::getName();
  std::set<std::string> out;
  if (!ros::master::execute("getSystemState", args, result, payload, true)) return out;
  XmlRpc::XmlRpcValue& list = payload[publishers ? 0 : 1];
  for (int i = 0; i < list.size(); ++i) {
    if (static_cast<std::string>(list[i][0]) != topic) continue;
    for (int n = 0; n < list[i][1].size(); ++n) out.insert(static_cast<std::string>(list[i][1][n]));
  }
  return out;
}

/// The server's /hermes/status (JSON text): `merged` robots merged and `applied`
/// submaps applied over all robots.
inline void expectMergedAndApplied(const std::string& status_text, int merged, std::size_t applied) {
  const auto status = nlohmann::json::parse(status_text, nullptr, false);
  ASSERT_TRUE(status.is_object()) << status_text;
  EXPECT_EQ(status.value("agents_merged", 0), merged);
  int n = 0;
  for (const auto& a : status["per_agent"]) n += a.value("submaps_applied", 0);
  EXPECT_EQ(n, static_cast<int>(applied));
}

}  // namespace hermes_tests
