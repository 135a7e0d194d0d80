// The downlink (downlink.h): what a placed robot gets (others' keyframes and
// landmarks around it, in its odometry frame), what one that lost track gets,
// the per-robot byte budget, and exactly-once delivery through loss and an outage.
#include <gtest/gtest.h>

#include <random>
#include <set>

#include "hermes/server/downlink.h"

using namespace hermes;
using namespace hermes::server;

namespace {

PinholeIntrinsics camera() { return PinholeIntrinsics{450, 450, 376, 240, 752, 480}; }

/// A trajectory of robot `agent` along x from x0 (keyframes every 0.5 m, the
/// camera looking +z), anchored at T_W_A, 40 landmarks per keyframe, each seen
/// by its keyframe and the next.
void addTrajectory(GlobalMap* map, std::uint32_t agent, std::uint32_t session, const SE3& T_W_A,
                   double x0, int keyframes, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  TrajectoryMap& t = map->trajectories[{agent, session}];
  t.agent = agent;
  t.session = session;
  t.uuid = uuidFromSeed(agent);
  t.anchored = true;
  t.T_W_A = T_W_A;
  const PinholeIntrinsics K = camera();
  LandmarkId next_lm = 1000;
  for (int k = 0; k < keyframes; ++k) {
    StoredKeyframe s;
    s.camera = K;
    s.keyframe.id = static_cast<KeyframeId>(k);
    s.keyframe.stamp = 0.5 * k;
    s.keyframe.T_A_C = SE3(Quat::Identity(), Vec3(x0 + 0.5 * k, 0, 0));
    s.T_W_C = T_W_A * s.keyframe.T_A_C;
    t.keyframes[s.keyframe.id] = s;
  }
  for (int k = 0; k < keyframes; ++k) {
    for (int i = 0; i < 40; ++i) {
      StoredLandmark lm;
      lm.landmark.id = next_lm++;
      lm.anchor = static_cast<KeyframeId>(k);
      lm.p_anchor = Vec3(2 * u(rng), 1.5 * u(rng), 4 + u(rng));
      for (auto& b : lm.landmark.descriptor) b = static_cast<std::uint8_t>(rng());
      for (int j = k; j < std::min(keyframes, k + 2); ++j) {
        StoredKeyframe& s = t.keyframes[static_cast<KeyframeId>(j)];
        const Vec3 p_C = s.T_W_C.inverse() * (t.keyframes[lm.anchor].T_W_C * lm.p_anchor);
        const Vec2 uv = K.project(p_C);
        Keypoint kp;
        kp.u = static_cast<float>(uv.x());
        kp.v = static_cast<float>(uv.y());
        s.keyframe.keypoints.push_back(kp);
        s.keyframe.descriptors.push_back(lm.landmark.descriptor);
        s.keyframe.keypoint_landmark.push_back(lm.landmark.id);
        lm.landmark.observations.push_back(
            {static_cast<KeyframeId>(j), static_cast<std::uint32_t>(s.keyframe.keypoints.size() - 1)});
      }
      t.landmarks[lm.landmark.id] = lm;
    }
  }
}

/// Robot 1 (session 2, its odometry frame O moved from the world) at x = 3 of
/// robot 2's 20-keyframe line, robot 1 session 1 an older session nearby.
GlobalMap hall() {
  GlobalMap map;
  const SE3 T_W_A1 = SE3::exp((Vec6() << 0.5, -0.2, 0.1, 0, 0.2, 0.05).finished());
  addTrajectory(&map, 1, 2, T_W_A1, 0, 4, 1);  // the recipient's current session
  addTrajectory(&map, 2, 1, SE3(), -2, 20, 2);
  addTrajectory(&map, 1, 1, SE3(), 30, 4, 3);  // far away: outside any radius
  return map;
}

DownlinkRecipient robot1() { return {1, uuidFromSeed(1), 2}; }

std::set<KeyframeKey> neighbourhood(const GlobalMap& map, const DownlinkRecipient& who,
                                    const Vec3& p, double radius) {
  std::set<KeyframeKey> out;
  for (const auto& [tid, t] : map.trajectories)
    for (const auto& [id, kf] : t.keyframes)
      if (!(t.agent == who.robot && t.session == who.session) &&
          (kf.T_W_C.translation() - p).norm() <= radius)
        out.insert({t.agent, t.session, id});
  return out;
}

}  // namespace

TEST(Downlink, SendsOthersKeyframesAroundThePlacedRobotInItsOdometryFrame) {
  const GlobalMap map = hall();
  DownlinkParams params;
  params.max_in_flight = 1;
  Downlink down(params, 7);
  auto out = down.plan(map, {robot1()}, 0.0);
  ASSERT_EQ(out.size(), 1u);
  auto p = decodeMapDown(out[0].bytes->data(), out[0].bytes->size());
  ASSERT_TRUE(p.ok()) << p.error();
  EXPECT_EQ(p->agent, robot1().agent);
  EXPECT_EQ(p->epoch, 7u);
  EXPECT_EQ(p->seq, 1u);
  EXPECT_EQ(p->session, 2u);
  ASSERT_FALSE(p->keyframes.empty());
  EXPECT_LE(out[0].bytes->size(), static_cast<std::size_t>(params.max_packet_bytes));
  const TrajectoryMap& own = map.trajectories.at({1, 2});
  const Vec3 robot_at = own.keyframes.at(3).T_W_C.translation();  // newest
  double last_d = -1;
  for (const BorrowedKeyframe& k : p->keyframes) {
    EXPECT_FALSE(k.origin.agent == 1 && k.origin.session == 2) << "its own current session";
    const StoredKeyframe* s = map.keyframe(k.origin);
    ASSERT_NE(s, nullptr);
    EXPECT_LT(((p->T_W_O * k.T_O_C).translation() - s->T_W_C.translation()).norm(), 1e-9);
    const double d = (s->T_W_C.translation() - robot_at).norm();
    EXPECT_LE(d, params.radius_m);
    EXPECT_GE(d, last_d - 1e-9) << "nearest first";
    last_d = d;
    EXPECT_LE(static_cast<int>(k.landmarks.size()), params.landmarks_per_keyframe);
  }
  for (const BorrowedLandmark& l : p->landmarks) {
    const TrajectoryMap* t = map.trajectory(l.origin.agent, l.origin.session);
    const StoredLandmark& s = t->landmarks.at(l.origin.id);
    const Vec3 p_W = t->keyframes.at(s.anchor).T_W_C * s.p_anchor;
    EXPECT_LT((p->T_W_O * l.p_O - p_W).norm(), 1e-4);
    EXPECT_EQ(l.descriptor, s.landmark.descriptor);
  }
  // Nothing new while the packet waits (max_in_flight 1), nothing for an unplaced robot.
  EXPECT_TRUE(down.plan(map, {robot1()}, 1.0).empty());
  EXPECT_TRUE(down.plan(map, {{5, uuidFromSeed(5), 1}}, 1.0).empty());
  DownlinkParams off = params;
  off.enabled = false;
  EXPECT_TRUE(Downlink(off, 1).plan(map, {robot1()}, 0.0).empty());
}

TEST(Downlink, ARobotThatLostTrackGetsTheMapAroundWhereItWasLastPlaced) {
  // Robot 1 started session 3 (tracking lost) that no loop has placed yet:
  // the map around its newest placed session (2) goes, in that session's
  // frame, its own last keyframes there first.
  const GlobalMap map = hall();
  DownlinkParams params;
  params.max_in_flight = 1;
  Downlink down(params, 1);
  const DownlinkRecipient lost{1, uuidFromSeed(1), 3};
  auto out = down.plan(map, {lost}, 0.0);
  ASSERT_EQ(out.size(), 1u);
  auto p = decodeMapDown(out[0].bytes->data(), out[0].bytes->size());
  ASSERT_TRUE(p.ok()) << p.error();
  EXPECT_EQ(p->session, 2u) << "the frame of the session last placed";
  const TrajectoryMap& last = map.trajectories.at({1, 2});
  const StoredKeyframe& newest = last.keyframes.at(3);
  EXPECT_LT(((p->T_W_O * newest.keyframe.T_A_C).translation() - newest.T_W_C.translation()).norm(), 1e-9);
  ASSERT_FALSE(p->keyframes.empty());
  EXPECT_EQ(p->keyframes.front().origin, (KeyframeKey{1, 2, 3})) << "where it was last: its own newest keyframe";
  for (const BorrowedKeyframe& k : p->keyframes) {
    EXPECT_FALSE(k.origin.agent == 1 && k.origin.session == 3);
    EXPECT_LE((map.keyframe(k.origin)->T_W_C.translation() - newest.T_W_C.translation()).norm(), params.radius_m);
  }
  // Any earlier placed session will do (robot 2: only session 1 is in the
  // map); a robot never placed gets nothing.
  EXPECT_EQ(down.plan(map, {{2, uuidFromSeed(2), 5}}, 0.0).size(), 1u);
  EXPECT_TRUE(down.plan(map, {{6, uuidFromSeed(6), 2}}, 0.0).empty());
}

TEST(Downlink, StaysWithinTheBudgetAndSendsTheNeighbourhoodOnce) {
  const GlobalMap map = hall();
  DownlinkParams params;
  Downlink down(params, 1);
  std::set<KeyframeKey> kfs, lms;
  std::uint64_t bytes = 0;
  const double T = 60;
  for (double t = 0; t <= T; t += 0.5) {
    for (const auto& o : down.plan(map, {robot1()}, t)) {
      bytes += o.bytes->size();
      auto p = decodeMapDown(o.bytes->data(), o.bytes->size());
      ASSERT_TRUE(p.ok());
      for (const auto& k : p->keyframes) EXPECT_TRUE(kfs.insert(k.origin).second) << "sent twice";
      for (const auto& l : p->landmarks) EXPECT_TRUE(lms.insert(l.origin).second) << "sent twice";
      EXPECT_TRUE(down.onAck({o.agent, 1, o.seq}, t));
    }
  }
  EXPECT_LE(static_cast<double>(bytes), params.bytes_per_s * (T + params.burst_s));
  EXPECT_EQ(down.stats().at(1).bytes, bytes);
  const Vec3 robot_at = map.trajectories.at({1, 2}).keyframes.at(3).T_W_C.translation();
  EXPECT_EQ(kfs, neighbourhood(map, robot1(), robot_at, params.radius_m));
  EXPECT_EQ(down.stats().at(1).keyframes, kfs.size());
  EXPECT_EQ(down.inFlight(), 0u);
}

TEST(Downlink, ExactlyOnceThroughLossAndAnOutage) {
  const GlobalMap map = hall();
  DownlinkParams params;
  params.bytes_per_s = 1500;
  Downlink down(params, 3);
  std::mt19937_64 rng(11);
  std::bernoulli_distribution lost(0.2);
  std::set<std::pair<std::uint64_t, std::uint64_t>> taken;  // the robot's (epoch, seq)
  std::map<KeyframeKey, int> kf_taken, lm_taken;
  std::uint64_t bytes = 0;
  const double T = 240;
  for (double t = 0; t <= T; t += 0.5) {
    const bool outage = t >= 20 && t < 50;  // 30 s: nothing either way
    for (const auto& o : down.plan(map, {robot1()}, t)) {
      bytes += o.bytes->size();
      if (outage || lost(rng)) continue;
      auto p = decodeMapDown(o.bytes->data(), o.bytes->size());
      ASSERT_TRUE(p.ok());
      if (taken.insert({p->epoch, p->seq}).second) {
        for (const auto& k : p->keyframes) ++kf_taken[k.origin];
        for (const auto& l : p->landmarks) ++lm_taken[l.origin];
      }
      if (!lost(rng)) down.onAck({p->agent, p->epoch, p->seq}, t);  // the ack may be lost too
    }
  }
  EXPECT_LE(static_cast<double>(bytes), params.bytes_per_s * (T + params.burst_s));
  EXPECT_GT(down.stats().at(1).resends, 0u);
  const Vec3 robot_at = map.trajectories.at({1, 2}).keyframes.at(3).T_W_C.translation();
  const auto want = neighbourhood(map, robot1(), robot_at, params.radius_m);
  EXPECT_EQ(kf_taken.size(), want.size());
  for (const auto& [k, n] : kf_taken) EXPECT_EQ(n, 1) << "keyframe " << k.id << " taken twice";
  for (const auto& [k, n] : lm_taken) EXPECT_EQ(n, 1) << "landmark " << k.id << " taken twice";
  EXPECT_EQ(down.inFlight(), 0u);
  EXPECT_FALSE(down.onAck({robot1().agent, 2, 1}, T)) << "another epoch's ack";
}

TEST(Downlink, ParamsRoundTripAndRefuseNonsense) {
  DownlinkParams p;
  p.bytes_per_s = 3000;
  p.radius_m = 4;
  ConfigWriter w;
  p.write(w);
  auto c = Config::fromString(w.yaml(), "test");
  ASSERT_TRUE(c.ok()) << c.error();
  DownlinkParams back;
  ASSERT_TRUE(back.read(*c).ok());
  EXPECT_EQ(back.bytes_per_s, 3000);
  EXPECT_EQ(back.radius_m, 4);
  p.min_packet_bytes = 100000;
  EXPECT_FALSE(p.validate().ok());
}
