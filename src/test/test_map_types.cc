#include <gtest/gtest.h>

#include "hermes/core/map_types.h"

using namespace hermes;

namespace {
Submap tinySubmap() {
  Submap s;
  s.cameras.push_back(PinholeIntrinsics{400, 400, 320, 240, 640, 480});
  for (KeyframeId id : {10u, 11u}) {
    Keyframe kf;
    kf.id = id;
    kf.keypoints.resize(2);
    kf.descriptors.resize(2);
    kf.keypoint_landmark = {7, kInvalidId};
    s.keyframes.push_back(kf);
  }
  Landmark lm;
  lm.id = 7;
  lm.observations = {{10, 0}, {11, 0}};
  s.landmarks.push_back(lm);
  s.odometry.push_back(OdometryEdge{10, 11, SE3(), Mat6::Identity()});
  return s;
}
}  // namespace

TEST(MapTypes, ValidSubmapPasses) { EXPECT_EQ(tinySubmap().validate(), ""); }

TEST(MapTypes, ValidationNamesTheProblem) {
  Submap s = tinySubmap();
  s.landmarks[0].observations.push_back({99, 0});
  EXPECT_NE(s.validate().find("unknown keyframe 99"), std::string::npos);
  s = tinySubmap();
  s.landmarks[0].observations[0].keypoint = 5;
  EXPECT_NE(s.validate().find("keypoint 5"), std::string::npos);
  s = tinySubmap();
  s.keyframes[1].id = 10;
  EXPECT_NE(s.validate().find("appears twice"), std::string::npos);
  s = tinySubmap();
  s.keyframes[0].camera_id = 3;
  EXPECT_NE(s.validate().find("camera 3"), std::string::npos);
}

TEST(MapTypes, KeyframeExtensionsCarryKeypointsOnly) {
  Submap s = tinySubmap();
  s.header.t_start = 1.0;
  for (Keyframe& kf : s.keyframes) kf.stamp = 1.5;
  Keyframe ext;  // extends keyframe 4 of an earlier submap
  ext.id = 4;
  ext.stamp = 0.5;
  ext.keypoints.resize(3);
  ext.descriptors.resize(3);
  ext.keypoint_landmark.assign(3, kInvalidId);
  s.keyframes.insert(s.keyframes.begin(), ext);
  EXPECT_EQ(s.validate(), "");
  EXPECT_TRUE(s.isExtension(s.keyframes[0]));
  EXPECT_FALSE(s.isExtension(s.keyframes[1]));
  EXPECT_EQ(s.windowKeyframeCount(), 2u);

  Submap bad = s;
  bad.keyframes[0].keypoint_landmark[1] = 7;
  EXPECT_NE(bad.validate().find("keyframe extension 4"), std::string::npos) << bad.validate();
  bad = s;
  bad.landmarks[0].observations.push_back({4, 2});
  EXPECT_NE(bad.validate().find("observed by keyframe extension 4"), std::string::npos);
  bad = s;
  bad.odometry.push_back(OdometryEdge{4, 10, SE3(), Mat6::Identity()});
  EXPECT_NE(bad.validate().find("names a keyframe extension"), std::string::npos);
}

TEST(MapTypes, UuidRoundTripAndHamming) {
  const Uuid a = uuidFromSeed(42);
  Uuid b{};
  ASSERT_TRUE(parseUuid(toString(a), &b));
  EXPECT_EQ(a, b);
  EXPECT_FALSE(parseUuid("xyz", &b));
  Descriptor d1{}, d2{};
  d2[0] = 0xff;
  d2[31] = 0x01;
  EXPECT_EQ(hammingDistance(d1, d2), 9);
}
