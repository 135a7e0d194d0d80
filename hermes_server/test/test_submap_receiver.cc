// rostest: real encoded submaps through real ROS topics to the receiver node.
#include <gtest/gtest.h>
#include <hermes_msgs/EncodedSubmap.h>
#include <hermes_msgs/SubmapAck.h>
#include <ros/ros.h>

#include "hermes/core/wire_format.h"
#include "hermes/core/wire_synthetic.h"

namespace {

hermes_msgs::EncodedSubmap makeMsg(std::uint64_t agent_seed, std::uint32_t session, std::uint64_t seq) {
  hermes::SyntheticSubmapOptions o;
  o.keyframes = 4;
  o.keypoints_per_keyframe = 100;
  o.landmarks = 150;
  o.seed = seq + 1;
  hermes::Submap s = hermes::makeSyntheticSubmap(o);
  s.header.agent = hermes::uuidFromSeed(agent_seed);
  s.header.session = session;
  s.header.seq = seq;
  auto frame = hermes::encodeSubmap(s, hermes::WireOptions{});
  EXPECT_TRUE(frame.ok()) << frame.error();
  hermes_msgs::EncodedSubmap m;
  m.agent_uuid = hermes::toString(s.header.agent);
  m.session = session;
  m.seq = seq;
  m.data = *frame;
  return m;
}

}  // namespace

TEST(SubmapReceiver, ExactlyOnceOverRosTopics) {
  ros::NodeHandle nh;
  std::vector<hermes_msgs::SubmapAck> acks;
  auto sub = nh.subscribe<hermes_msgs::SubmapAck>(
      "/hermes/submap_ack", 100, [&](const hermes_msgs::SubmapAckConstPtr& a) { acks.push_back(*a); });
  auto pub = nh.advertise<hermes_msgs::EncodedSubmap>("/hermes/submap", 100);
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(30.0);
  while ((pub.getNumSubscribers() == 0 || sub.getNumPublishers() == 0) && ros::WallTime::now() < deadline)
    ros::WallDuration(0.05).sleep();
  ASSERT_GT(pub.getNumSubscribers(), 0u);

  std::vector<hermes_msgs::EncodedSubmap> sent;
  for (std::uint64_t seq = 0; seq < 5; ++seq) sent.push_back(makeMsg(1, 0, seq));
  for (const auto& m : sent) pub.publish(m);
  pub.publish(sent[2]);  // a resend
  auto corrupt = makeMsg(1, 0, 5);
  corrupt.data[corrupt.data.size() / 2] ^= 0x40;
  pub.publish(corrupt);
  pub.publish(makeMsg(2, 0, 0));  // a second agent is unaffected

  while (acks.size() < 8 && ros::WallTime::now() < deadline) {
    ros::spinOnce();
    ros::WallDuration(0.01).sleep();
  }
  ASSERT_EQ(acks.size(), 8u);
  int accepted = 0, duplicate = 0, rejected = 0;
  for (const auto& a : acks) {
    if (a.status == hermes_msgs::SubmapAck::ACCEPTED) ++accepted;
    if (a.status == hermes_msgs::SubmapAck::DUPLICATE) ++duplicate;
    if (a.status == hermes_msgs::SubmapAck::REJECTED) {
      ++rejected;
      EXPECT_EQ(a.seq, 5u);
      EXPECT_NE(a.reason.find("CRC"), std::string::npos) << a.reason;
    }
  }
  EXPECT_EQ(accepted, 6);
  EXPECT_EQ(duplicate, 1);
  EXPECT_EQ(rejected, 1);
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_submap_receiver");
  return RUN_ALL_TESTS();
}
