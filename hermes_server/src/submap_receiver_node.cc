// ROS adapter of the server's submap receiver: EncodedSubmap in, SubmapAck out.
// Decoding, deduplication and bookkeeping live in the ROS-free core
// (hermes::SubmapReceiver); this node only converts messages.
#include <hermes_msgs/EncodedSubmap.h>
#include <hermes_msgs/SubmapAck.h>
#include <ros/ros.h>
#include <std_msgs/String.h>

#include "hermes/server/submap_receiver.h"

namespace {

hermes_msgs::SubmapAck makeAck(const hermes_msgs::EncodedSubmap& m, const hermes::ReceiveResult& r) {
  hermes_msgs::SubmapAck ack;
  ack.header.stamp = ros::Time::now();
  ack.agent_uuid = m.agent_uuid;
  ack.session = m.session;
  ack.seq = m.seq;
  ack.robot_id = r.robot;
  switch (r.verdict) {
    case hermes::ArrivalVerdict::kAccept: ack.status = hermes_msgs::SubmapAck::ACCEPTED; break;
    case hermes::ArrivalVerdict::kDuplicate:
    case hermes::ArrivalVerdict::kStale: ack.status = hermes_msgs::SubmapAck::DUPLICATE; break;
    case hermes::ArrivalVerdict::kRejected: ack.status = hermes_msgs::SubmapAck::REJECTED; break;
  }
  ack.reason = r.reason;
  return ack;
}

}  // namespace

int main(int argc, char** argv) {
  ros::init(argc, argv, "submap_receiver");
  ros::NodeHandle nh;
  hermes::Bookkeeper books;
  std::size_t applied = 0;
  hermes::SubmapReceiver receiver(&books, [&](hermes::ReceivedSubmap&& s) {
    ++applied;
    ROS_INFO("applied submap seq %lu of robot %u (%zu keyframes, %zu bytes)",
             static_cast<unsigned long>(s.submap.header.seq), s.robot,
             s.submap.keyframes.size(), s.bytes);
  });
  ros::Publisher ack_pub = nh.advertise<hermes_msgs::SubmapAck>("submap_ack", 100);
  ros::Publisher stats_pub = nh.advertise<std_msgs::String>("receiver_stats", 10, true);
  ros::Subscriber sub = nh.subscribe<hermes_msgs::EncodedSubmap>(
      "submap", 100, [&](const hermes_msgs::EncodedSubmapConstPtr& m) {
        hermes::SubmapHeader claimed;
        const bool have_uuid = hermes::parseUuid(m->agent_uuid, &claimed.agent);
        claimed.session = m->session;
        claimed.seq = m->seq;
        const auto r = receiver.receive(m->data.data(), m->data.size(),
                                        have_uuid ? &claimed : nullptr, ros::Time::now().toSec());
        if (!have_uuid && r.verdict != hermes::ArrivalVerdict::kRejected)
          ROS_WARN_THROTTLE(5.0, "submap message has an unparsable agent_uuid '%s'",
                            m->agent_uuid.c_str());
        if (r.verdict == hermes::ArrivalVerdict::kRejected)
          ROS_WARN_THROTTLE(1.0, "rejected submap from '%s' seq %lu: %s", m->agent_uuid.c_str(),
                            static_cast<unsigned long>(m->seq), r.reason.c_str());
        ack_pub.publish(makeAck(*m, r));  // rejections are answered too, with the reason
        const auto& st = receiver.stats();
        std_msgs::String s;
        s.data = "{\"frames\": " + std::to_string(st.frames) + ", \"applied\": " +
                 std::to_string(applied) + ", \"duplicates\": " + std::to_string(st.duplicates) +
                 ", \"rejected\": " + std::to_string(st.rejected) + "}";
        stats_pub.publish(s);
      });
  ros::spin();
}
