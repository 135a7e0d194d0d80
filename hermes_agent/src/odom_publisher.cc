#include "odom_publisher.h"

#include "ros_convert.h"

namespace hermes_agent {

void OdomPublisher::advertise(ros::NodeHandle& nh, const std::string& robot) {
  robot_ = robot;
  odom_pub_ = nh.advertise<nav_msgs::Odometry>("odom", 50);
  odom_global_pub_ = nh.advertise<nav_msgs::Odometry>("odom_global", 50);
}

void OdomPublisher::sendTf(const geometry_msgs::Pose& p, const std_msgs::Header& header, const std::string& child) {
  geometry_msgs::TransformStamped tf;
  tf.header = header;
  tf.child_frame_id = child;
  tf.transform.translation.x = p.position.x;
  tf.transform.translation.y = p.position.y;
  tf.transform.translation.z = p.position.z;
  tf.transform.rotation = p.orientation;
  tf_.sendTransform(tf);
}

void OdomPublisher::publish(const hermes::SE3& T_O_B, const hermes::GlobalPoseState& global,
                            const ros::Time& stamp) {
  nav_msgs::Odometry odom;
  odom.header.stamp = stamp;
  odom.header.frame_id = robot_ + "/odom";
  odom.child_frame_id = robot_ + "/base_link";
  odom.pose.pose = toPose(T_O_B);
  odom_pub_.publish(odom);
  sendTf(odom.pose.pose, odom.header, odom.child_frame_id);

  const auto T_world_B = global.inWorld(T_O_B);
  if (!T_world_B) return;
  nav_msgs::Odometry o;
  o.header.stamp = stamp;
  o.header.frame_id = "world";
  o.child_frame_id = robot_ + "/base_link";
  o.pose.pose = toPose(*T_world_B);
  odom_global_pub_.publish(o);
  sendTf(toPose(global.latest()->T_W_O), o.header, robot_ + "/odom");
}

}  // namespace hermes_agent
