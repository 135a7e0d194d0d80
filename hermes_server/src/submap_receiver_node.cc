// Minimal receiver (placeholder for mechanics check): acks every submap.
#include <hermes_msgs/EncodedSubmap.h>
#include <hermes_msgs/SubmapAck.h>
#include <ros/ros.h>

int main(int argc, char** argv) {
  ros::init(argc, argv, "submap_receiver");
  ros::NodeHandle nh;
  ros::Publisher ack_pub = nh.advertise<hermes_msgs::SubmapAck>("submap_ack", 100);
  ros::Subscriber sub = nh.subscribe<hermes_msgs::EncodedSubmap>(
      "submap", 100, [&](const hermes_msgs::EncodedSubmapConstPtr& m) {
        hermes_msgs::SubmapAck ack;
        ack.agent_uuid = m->agent_uuid;
        ack.session = m->session;
        ack.seq = m->seq;
        ack.status = hermes_msgs::SubmapAck::ACCEPTED;
        ack_pub.publish(ack);
      });
  ros::spin();
}
