// The Agent nodelet's pose outputs: odom (nav_msgs/Odometry, frame <robot>/odom,
// child <robot>/base_link) with TF <robot>/odom -> <robot>/base_link for every
// tracked frame, and, once the server placed the robot, odom_global (frame
// world) with TF world -> <robot>/odom, all stamped with the image's stamp.
#pragma once

#include <nav_msgs/Odometry.h>
#include <ros/ros.h>
#include <tf2_ros/transform_broadcaster.h>

#include <string>

#include "hermes/core/geometry.h"
#include "hermes/core/global_pose.h"

namespace hermes_agent {

class OdomPublisher {
 public:
  /// Advertises odom and odom_global in `nh`'s namespace.
  void advertise(ros::NodeHandle& nh, const std::string& robot);
  /// odom + TF of the body pose T_O_B in the robot's odometry frame; then
  /// odom_global + TF world -> odom when `global` knows the robot's place.
  void publish(const hermes::SE3& T_O_B, const hermes::GlobalPoseState& global, const ros::Time& stamp);

 private:
  void sendTf(const geometry_msgs::Pose& p, const std_msgs::Header& header, const std::string& child);

  std::string robot_;
  ros::Publisher odom_pub_, odom_global_pub_;
  tf2_ros::TransformBroadcaster tf_;
};

}  // namespace hermes_agent
