#include "ros_relay.h"

#include <algorithm>

#include "hermes/core/map_types.h"

namespace hermes_agent {

hermes::Expected<std::unique_ptr<RosRelay>> RosRelay::open(const std::string& robot,
                                                           const std::vector<std::string>& origins,
                                                           const std::string& spool_dir,
                                                           const hermes::agent::UplinkParams& uplink,
                                                           const hermes::Config& config, Publish publish) {
  hermes::agent::RelayParams rp;
  double period = 0.5;  // system.server_period_s: the coordinator re-splits this often
  hermes::Status s = rp.read(config);
  if (s) s = config.get("system.server_period_s", &period);
  if (!s) return hermes::Error{"config: " + s.error()};
  auto f = hermes::agent::RelayForwarder::open(
      spool_dir, origins, rp, uplink, period,
      [publish = std::move(publish)](const std::string& origin, std::uint32_t session, std::uint64_t seq,
                                     const std::vector<std::uint8_t>& frame) {  // untouched (its tag)
        publish(hermes::toString(hermes::agentUuid(origin)), session, seq, frame);
      });
  if (!f) return hermes::Error{"relay: " + f.error()};
  std::unique_ptr<RosRelay> r(new RosRelay);
  r->robot_ = robot;
  r->spool_dir_ = spool_dir;
  r->min_mbitps_ = rp.min_mbitps;
  r->forwarder_ = std::move(*f);
  return r;
}

void RosRelay::start(ros::NodeHandle& nh, ros::Publisher heartbeats, UplinkEstimate uplink) {
  heartbeats_ = std::move(heartbeats);
  uplink_ = std::move(uplink);
  const std::string r = "/" + robot_ + "/relay/";
  for (const std::string& o : forwarder_->origins()) {  // per relayed robot: its answers
    Out& out = out_[o];
    out.held = nh.advertise<hermes_msgs::SubmapAck>(r + o + "/held", 100);
    out.ack = nh.advertise<hermes_msgs::SubmapAck>(
        r + o + "/submap_ack", 100,
        [this, o](const ros::SingleSubscriberPublisher& p) { onAckListener(o, p.getSubscriberName(), +1); },
        [this, o](const ros::SingleSubscriberPublisher& p) { onAckListener(o, p.getSubscriberName(), -1); });
    out.global = nh.advertise<hermes_msgs::GlobalPose>(r + o + "/global_pose", 20);
  }
  submap_sub_ = nh.subscribe(r + "submap", 100, &RosRelay::onSubmap, this);
  heartbeat_sub_ = nh.subscribe(r + "heartbeat", 20, &RosRelay::onHeartbeat, this);
  timer_ = nh.createWallTimer(ros::WallDuration(0.05), &RosRelay::onTimer, this);
  std::string names;
  for (const auto& [o, out] : out_) names += (names.empty() ? "" : ", ") + o;
  ROS_INFO("Agent %s: relay for %s: %ssubmap in, spool %s, %.1f Mbit/s guaranteed each",
           robot_.c_str(), names.c_str(), r.c_str(), spool_dir_.c_str(), min_mbitps_);
}

void RosRelay::stop() {
  timer_.stop();
  submap_sub_.shutdown();
  heartbeat_sub_.shutdown();
}

void RosRelay::onOwnFrame(std::uint32_t session, std::uint64_t seq, const std::vector<std::uint8_t>& frame) {
  forwarder_->onOwnFrame(session, seq, frame, ros::WallTime::now().toSec());
}

void RosRelay::onSubmap(const hermes_msgs::EncodedSubmapConstPtr& m) {
  const std::string origin = forwarder_->originOfUuid(m->agent_uuid);
  if (origin.empty()) {
    ROS_WARN_THROTTLE(5.0, "Agent %s: relay: a submap of agent %s, not a robot of ~relay_for: dropped",
                      robot_.c_str(), m->agent_uuid.c_str());
    return;
  }
  auto offer = forwarder_->offer(origin, m->session, m->seq, m->data, ros::WallTime::now().toSec());
  if (!offer) {  // not acknowledged: the origin keeps it and offers it again
    ROS_WARN_THROTTLE(2.0, "Agent %s: %s", robot_.c_str(), offer.error().c_str());
    return;
  }
  hermes_msgs::SubmapAck a;
  a.header.stamp = ros::Time::now();
  a.agent_uuid = m->agent_uuid;
  a.session = m->session;
  a.seq = m->seq;
  if (*offer != hermes::agent::RelaySpool::Offer::kAlreadyAcked) {
    a.status = hermes_msgs::SubmapAck::ACCEPTED;  // lost if the origin is not connected: it offers again
    out_.at(origin).held.publish(a);
    return;
  }
  a.status = hermes_msgs::SubmapAck::DUPLICATE;  // the server's acknowledgement, again
  a.reason_code = hermes_msgs::SubmapAck::REASON_REPLAY;
  a.reason = "acknowledged by the server through relay " + robot_;
  passAck(origin, a);
}

bool RosRelay::takeAck(const hermes_msgs::SubmapAck& a) {
  const std::string origin = forwarder_->originOfUuid(a.agent_uuid);
  if (origin.empty()) return false;
  if (a.status != hermes_msgs::SubmapAck::REJECTED)
    forwarder_->onServerAck(origin, a.session, a.seq, ros::WallTime::now().toSec());
  passAck(origin, a);
  return true;
}

bool RosRelay::takeGlobalPose(const hermes_msgs::GlobalPoseConstPtr& m) {
  const std::string origin = forwarder_->originOfUuid(m->agent_uuid);
  if (origin.empty()) return false;
  if (auto it = out_.find(origin); it != out_.end()) it->second.global.publish(m);
  return true;
}

void RosRelay::passAck(const std::string& origin, const hermes_msgs::SubmapAck& a) {
  auto it = out_.find(origin);
  if (it == out_.end()) return;  // an earlier run's origin: nobody to tell
  std::lock_guard<std::mutex> lock(out_mu_);
  it->second.waiting.push_back(a);
  flushAcks(it->second);
}

void RosRelay::onAckListener(const std::string& origin, const std::string& node, int change) {
  if (node.rfind("/" + origin + "/", 0) != 0) return;  // an observer such as rostopic echo
  std::lock_guard<std::mutex> lock(out_mu_);
  Out& out = out_.at(origin);
  out.listening = std::max(0, out.listening + change);
  flushAcks(out);
}

void RosRelay::flushAcks(Out& out) {
  if (out.listening == 0) return;
  for (const hermes_msgs::SubmapAck& a : out.waiting) out.ack.publish(a);
  out.waiting.clear();
}

void RosRelay::onHeartbeat(const hermes_msgs::AgentHeartbeatConstPtr& h) {
  if (!forwarder_->originOfUuid(h->agent_uuid).empty()) heartbeats_.publish(h);
}

void RosRelay::onTimer(const ros::WallTimerEvent&) {
  const double now = ros::WallTime::now().toSec();
  forwarder_->poll(now, uplink_(now));
  std::lock_guard<std::mutex> lock(out_mu_);
  for (auto& [origin, out] : out_) flushAcks(out);
}

nlohmann::json RosRelay::status() const {
  nlohmann::json r = nlohmann::json::object();
  for (const hermes::agent::RelayForwarder::OriginState& o : forwarder_->states())
    r[o.origin] = {{"stored", o.stats.stored}, {"duplicates", o.stats.duplicates},
                   {"server_acked", o.stats.server_acked}, {"pending", o.pending},
                   {"pending_bytes", o.pending_bytes}, {"waiting", o.waiting},
                   {"forwarded", o.forwarded}, {"forwarded_bytes", o.forwarded_bytes},
                   {"rate_kBps", o.rate_Bps / 1000.0}, {"weight", o.weight}};
  return r;
}

}  // namespace hermes_agent
