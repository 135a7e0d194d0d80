// The robot's side of "its place in the global map": which world <- odom updates
// it takes, and how it places its odometry poses with them.
#include <gtest/gtest.h>

#include <limits>

#include "hermes/core/global_pose.h"

using namespace hermes;

namespace {
GlobalPoseUpdate update(std::uint32_t session, double stamp, const SE3& T) {
  GlobalPoseUpdate u;
  u.session = session;
  u.keyframe_stamp = stamp;
  u.T_W_O = T;
  return u;
}
}  // namespace

TEST(GlobalPose, TakesTheNewestOfItsOwnSessionOnly) {
  GlobalPoseState g;
  EXPECT_FALSE(g.inWorld(SE3::identity()).has_value());  // not placed yet
  const SE3 A(expSO3(Vec3(0, 0, 0.5)), Vec3(1, 2, 3)), B(expSO3(Vec3(0.1, 0, 0)), Vec3(-1, 0, 0));
  EXPECT_FALSE(g.update(update(2, 10.0, A), 1, 100.0));  // another session (an old map)
  EXPECT_TRUE(g.update(update(1, 10.0, A), 1, 100.0));
  EXPECT_FALSE(g.update(update(1, 9.5, B), 1, 101.0));   // older keyframe: arrived late
  EXPECT_TRUE(g.update(update(1, 10.0, B), 1, 102.0));   // same keyframe, re-optimised
  EXPECT_EQ(g.updates(), 2u);
  ASSERT_TRUE(g.receivedAt().has_value());
  EXPECT_DOUBLE_EQ(*g.receivedAt(), 102.0);
  // T_W_B = T_W_O * T_O_B.
  const SE3 T_O_B(expSO3(Vec3(0, 0.2, 0)), Vec3(0.5, 0, 0));
  const auto T_W_B = g.inWorld(T_O_B);
  ASSERT_TRUE(T_W_B.has_value());
  const SE3 want = B * T_O_B;
  EXPECT_LT((T_W_B->translation() - want.translation()).norm(), 1e-12);
  EXPECT_LT(T_W_B->quat().angularDistance(want.quat()), 1e-12);
  g.reset();
  EXPECT_FALSE(g.latest().has_value());
}

TEST(GlobalPose, RefusesWhatIsNotFinite) {
  GlobalPoseState g;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(g.update(update(1, nan, SE3::identity()), 1, 0.0));
  EXPECT_FALSE(g.update(update(1, 1.0, SE3(Quat::Identity(), Vec3(nan, 0, 0))), 1, 0.0));
  EXPECT_FALSE(g.update(update(1, 1.0, SE3(Quat(0, 0, 0, 0), Vec3::Zero())), 1, 0.0));
  const Status s = update(1, 1.0, SE3(Quat::Identity(), Vec3(nan, 0, 0))).validate();
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().find("not finite"), std::string::npos) << s.error();
  EXPECT_FALSE(g.latest().has_value());
}
