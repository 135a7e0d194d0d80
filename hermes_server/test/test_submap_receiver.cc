#include <gtest/gtest.h>
#include <hermes_msgs/EncodedSubmap.h>
#include <hermes_msgs/SubmapAck.h>
#include <ros/ros.h>

TEST(SubmapReceiver, AcksASubmap) {
  ros::NodeHandle nh;
  std::vector<hermes_msgs::SubmapAck> acks;
  auto sub = nh.subscribe<hermes_msgs::SubmapAck>(
      "submap_ack", 10, [&](const hermes_msgs::SubmapAckConstPtr& a) { acks.push_back(*a); });
  auto pub = nh.advertise<hermes_msgs::EncodedSubmap>("submap", 10);
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(20.0);
  while ((pub.getNumSubscribers() == 0 || sub.getNumPublishers() == 0) && ros::WallTime::now() < deadline)
    ros::WallDuration(0.05).sleep();
  hermes_msgs::EncodedSubmap m;
  m.agent_uuid = "x";
  m.seq = 3;
  pub.publish(m);
  while (acks.empty() && ros::WallTime::now() < deadline) {
    ros::spinOnce();
    ros::WallDuration(0.01).sleep();
  }
  ASSERT_EQ(acks.size(), 1u);
  EXPECT_EQ(acks[0].seq, 3u);
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_submap_receiver");
  return RUN_ALL_TESTS();
}
