// What the server tells each robot after a merge: world <- odom at the robot's
// newest merged keyframe, for anchored trajectories only.
#include <gtest/gtest.h>

#include "hermes/server/server_outputs.h"

using namespace hermes;
using namespace hermes::server;

TEST(GlobalPoseUpdates, WorldFromOdomAtTheNewestKeyframeOfEachAnchoredSession) {
  GlobalMap map;
  const SE3 early(expSO3(Vec3(0, 0, 0.1)), Vec3(0.3, 0, 0));   // correction at the old keyframe
  const SE3 late(expSO3(Vec3(0, 0, -0.2)), Vec3(1, -2, 0.5));  // at the newest one
  auto add = [](TrajectoryMap* t, KeyframeId id, double stamp, const SE3& T_A_C, const SE3& corr) {
    StoredKeyframe k;
    k.keyframe.id = id;
    k.keyframe.stamp = stamp;
    k.keyframe.T_A_C = T_A_C;
    k.T_W_C = corr * T_A_C;
    t->keyframes[id] = k;
  };
  TrajectoryMap& a = map.trajectories[{0, 1}];
  a.agent = 0, a.session = 1, a.anchored = true;
  add(&a, 7, 20.0, SE3(expSO3(Vec3(0.3, 0, 0)), Vec3(4, 1, 0)), late);   // newest by stamp, not by id
  add(&a, 9, 12.0, SE3(Quat::Identity(), Vec3(2, 0, 0)), early);
  TrajectoryMap& b = map.trajectories[{1, 1}];  // not anchored: nothing to tell
  b.agent = 1, b.session = 1;
  add(&b, 1, 5.0, SE3::identity(), early);
  map.trajectories[{2, 3}].agent = 2;  // anchored but empty: nothing either
  map.trajectories[{2, 3}].anchored = true;

  const auto updates = globalPoseUpdates(map);
  ASSERT_EQ(updates.size(), 1u);
  EXPECT_EQ(updates[0].first, 0u);
  const GlobalPoseUpdate& u = updates[0].second;
  EXPECT_EQ(u.session, 1u);
  EXPECT_DOUBLE_EQ(u.keyframe_stamp, 20.0);
  EXPECT_EQ(u.keyframes, 2u);
  EXPECT_LT((u.T_W_O.translation() - late.translation()).norm(), 1e-12);
  EXPECT_LT(u.T_W_O.quat().angularDistance(late.quat()), 1e-12);
  EXPECT_TRUE(u.validate().ok());
}
