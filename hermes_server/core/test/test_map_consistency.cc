// Map-consistency measure (map_consistency.h) on a synthetic two-robot scene
// with exact observations: a consistent map has ties at rounding level, a robot
// moved by a known offset shows it in its cross-robot ties (reprojection and
// 3-D distance), ties above the gate are left out; and the kept loop pairs the
// measure reads survive save / load (version 4; other versions refused).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <map>
#include <random>
#include <vector>

#include "hermes/core/crc32.h"
#include "hermes/server/global_map.h"
#include "hermes/server/map_consistency.h"

namespace hermes {
namespace server {
namespace {

constexpr int kKeyframes = 14;
constexpr int kLoopKf = 7;

PinholeIntrinsics camera() {
  PinholeIntrinsics c;
  c.fx = c.fy = 450;
  c.cx = 320;
  c.cy = 240;
  c.width = 640;
  c.height = 480;
  return c;
}

/// Two robots walking side by side along x, looking at a wall of points at
/// z = 4 m (world frame = both agent frames); every keyframe observes every
/// point it sees, exactly, with depth. Robot 1's keyframe kLoopKf is tied to
/// robot 0's keyframe kLoopKf by a loop whose kept pairs are the shared points.
struct Scene {
  GlobalMap map;
  std::vector<Vec3> points;                       // truth, indexed by landmark id
  std::map<KeyframeKey, SE3> truth;               // keyframe poses
};

SE3 truePose(int robot, int i) {
  const Vec3 t(0.15 * i, 0.3 * robot - 0.15, 0.05 * std::sin(0.5 * i + robot));
  const Quat q(Eigen::AngleAxisd(0.02 * i - 0.03 * robot, Vec3::UnitY()));
  return SE3(q, t);
}

Scene makeScene() {
  Scene s;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> ux(-2.0, 4.5), uy(-1.5, 1.5), uz(3.5, 4.5);
  for (int j = 0; j < 400; ++j) s.points.emplace_back(ux(rng), uy(rng), uz(rng));
  const PinholeIntrinsics cam = camera();
  for (std::uint32_t robot = 0; robot < 2; ++robot) {
    TrajectoryMap& t = s.map.trajectories[{robot, 0}];
    t.agent = robot;
    t.anchored = true;
    for (int i = 0; i < kKeyframes; ++i) {
      StoredKeyframe sk;
      sk.keyframe.id = static_cast<KeyframeId>(i);
      sk.keyframe.stamp = i;
      sk.keyframe.T_A_C = truePose(robot, i);
      sk.T_W_C = sk.keyframe.T_A_C;
      sk.camera = cam;
      for (std::size_t j = 0; j < s.points.size(); ++j) {
        const Vec3 p_C = sk.T_W_C.inverse() * s.points[j];
        const Vec2 uv = cam.project(p_C);
        if (p_C.z() < 0.5 || !cam.inImage(uv, 5)) continue;
        Keypoint kp;
        kp.u = static_cast<float>(uv.x());
        kp.v = static_cast<float>(uv.y());
        kp.depth = static_cast<float>(p_C.z());
        const auto index = static_cast<std::uint32_t>(sk.keyframe.keypoints.size());
        sk.keyframe.keypoints.push_back(kp);
        sk.keyframe.descriptors.emplace_back();
        sk.keyframe.keypoint_landmark.push_back(j);
        auto& lm = t.landmarks[j];
        lm.landmark.id = j;
        lm.landmark.p_A = s.points[j];
        lm.landmark.observations.push_back(Observation{sk.keyframe.id, index});
      }
      s.truth[KeyframeKey{robot, 0, sk.keyframe.id}] = sk.T_W_C;
      t.keyframes[sk.keyframe.id] = std::move(sk);
    }
    for (auto& [id, lm] : t.landmarks) GlobalMap::anchorLandmark(t, &lm);
    for (int i = 0; i + 1 < kKeyframes; ++i) {  // exact odometry, 1 cm / 10 mrad sigmas
      OdometryEdge e;
      e.from = i;
      e.to = i + 1;
      e.T_from_to = truePose(robot, i).inverse() * truePose(robot, i + 1);
      e.information = Mat6::Identity() * 1e4;
      t.odometry[{e.from, e.to}] = e;
    }
  }
  // The loop: robot 0's keyframe kLoopKf (a) <-> robot 1's (b); pairs = shared points.
  LoopEdge loop;
  loop.id = 1;
  loop.a = KeyframeKey{0, 0, kLoopKf};
  loop.b = KeyframeKey{1, 0, kLoopKf};
  loop.T_a_b = s.truth[loop.a].inverse() * s.truth[loop.b];
  loop.accepted = true;
  const Keyframe& ka = s.map.keyframe(loop.a)->keyframe;
  const Keyframe& kb = s.map.keyframe(loop.b)->keyframe;
  for (std::uint32_t i = 0; i < ka.keypoints.size(); ++i)
    for (std::uint32_t k = 0; k < kb.keypoints.size(); ++k)
      if (ka.keypoint_landmark[i] == kb.keypoint_landmark[k])
        loop.matches.push_back(LoopMatch{kLoopKf, i, kLoopKf, k});
  loop.inliers = static_cast<int>(loop.matches.size());
  s.map.loops.push_back(loop);
  return s;
}

/// Moves every keyframe of robot 1 by `offset` in the world (its landmarks follow their anchors).
void shiftRobot1(Scene* s, const Vec3& offset) {
  for (auto& [id, kf] : s->map.trajectories.at({1, 0}).keyframes)
    kf.T_W_C = SE3(kf.T_W_C.quat(), kf.T_W_C.translation() + offset);
}

TEST(MapConsistency, AConsistentMapHasTiesAtRoundingLevel) {
  const Scene s = makeScene();
  const TieConsistency c = measureLoopTies(s.map);
  ASSERT_GT(c.cross_ties, 50);
  EXPECT_EQ(c.ties, c.cross_ties);  // the one loop joins the two robots
  EXPECT_EQ(c.depth_ties, c.ties);  // every keypoint has a depth
  EXPECT_LT(c.cross_reproj_rms_px, 1e-3);
  EXPECT_LT(c.cross_dist_rms_m, 1e-5);
}

TEST(MapConsistency, AMisplacedRobotShowsInItsCrossTies) {
  Scene s = makeScene();
  shiftRobot1(&s, Vec3(0.05, 0, 0));  // 5 cm sideways
  const TieConsistency c = measureLoopTies(s.map);
  ASSERT_GT(c.cross_ties, 50);
  // Both directions of a tie see the 5 cm: as a 3-D distance exactly, as about
  // f * 0.05 / z = 450 * 0.05 / 4 = 5.6 px on the image.
  EXPECT_NEAR(c.cross_dist_rms_m, 0.05, 1e-4);
  EXPECT_NEAR(c.cross_dist_median_m, 0.05, 1e-4);
  EXPECT_GT(c.cross_reproj_rms_px, 4.0);
  EXPECT_LT(c.cross_reproj_rms_px, 8.0);
  // A gate below that error leaves every tie out.
  EXPECT_EQ(measureLoopTies(s.map, 2.0).ties, 0);
  // A loop PCM rejected does not count.
  s.map.loops[0].accepted = false;
  EXPECT_EQ(measureLoopTies(s.map).ties, 0);
}

TEST(MapConsistency, LoopPairsSurviveSaveAndLoad) {
  const Scene s = makeScene();
  ASSERT_FALSE(s.map.loops[0].matches.empty());
  const std::vector<std::uint8_t> bytes = s.map.toBytes();
  auto loaded = GlobalMap::fromBytes(bytes, "test");
  ASSERT_TRUE(loaded.ok()) << loaded.error();
  EXPECT_EQ(loaded->loops[0].matches, s.map.loops[0].matches);
  EXPECT_EQ(loaded->toBytes(), bytes);
  EXPECT_EQ(measureLoopTies(*loaded).cross_ties, measureLoopTies(s.map).cross_ties);
  // A version-3 file (one with refined edges) is refused with a clear message.
  std::vector<std::uint8_t> old = bytes;
  const std::uint32_t v3 = 3;
  std::memcpy(old.data() + 4, &v3, 4);
  const std::uint32_t crc = crc32(old.data(), old.size() - 4);
  std::memcpy(old.data() + old.size() - 4, &crc, 4);
  auto refused = GlobalMap::fromBytes(old, "old");
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().find("unsupported version 3 (this build reads 4)"), std::string::npos)
      << refused.error();
  // A kept pair naming a keypoint the keyframe does not hold is refused.
  GlobalMap bad = s.map;
  bad.loops[0].matches[0].kp_a = 100000;
  EXPECT_FALSE(GlobalMap::fromBytes(bad.toBytes(), "bad").ok());
}

}  // namespace
}  // namespace server
}  // namespace hermes
