#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>

#include "hermes/core/trajectory.h"

using namespace hermes;

TEST(Trajectory, TumRoundTripAndInterpolation) {
  Trajectory t;
  t.push_back({1.0, SE3(expSO3(Vec3(0, 0, 0)), Vec3(0, 0, 0))});
  t.push_back({2.0, SE3(expSO3(Vec3(0, 0, 0.2)), Vec3(2, 0, 0))});
  const std::string path = ::testing::TempDir() + "/traj.txt";
  ASSERT_TRUE(writeTumTrajectory(path, t));
  auto r = readTumTrajectory(path);
  ASSERT_TRUE(r.ok()) << r.error();
  ASSERT_EQ(r->size(), 2u);
  EXPECT_LT(((*r)[1].T_W_B.translation() - Vec3(2, 0, 0)).norm(), 1e-9);
  SE3 mid;
  ASSERT_TRUE(interpolatePose(*r, 1.5, &mid));
  EXPECT_NEAR(mid.translation().x(), 1.0, 1e-9);
  EXPECT_NEAR(rotationAngle(mid.rotation()), 0.1, 1e-9);
  EXPECT_FALSE(interpolatePose(*r, 2.5, &mid));
}

TEST(Trajectory, ErrorsNamePathAndLine) {
  const std::string path = ::testing::TempDir() + "/bad.txt";
  std::ofstream(path) << "# header\n1.0 0 0 0 0 0 0 1\n2.0 0 0 oops\n";
  auto r = readTumTrajectory(path);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().find(path + ":3"), std::string::npos) << r.error();
  EXPECT_FALSE(readTumTrajectory("/no/such/file.txt").ok());
}

TEST(Trajectory, ReadsRealEurocGroundTruth) {
  auto r = readTumTrajectory(std::string(HERMES_TRAJECTORY_DIR) + "/MH_01_easy.txt");
  ASSERT_TRUE(r.ok()) << r.error();
  EXPECT_GT(r->size(), 3600u);  // 182 s at 20 Hz
  EXPECT_NEAR(r->back().t - r->front().t, 182.0, 2.0);
}
