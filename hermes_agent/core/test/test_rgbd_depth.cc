#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "hermes/agent/rgbd_depth.h"

using namespace hermes;

namespace {
FeatureSet featuresAt(const std::vector<std::pair<float, float>>& uv, int w, int h) {
  FeatureSet fs;
  fs.width = w;
  fs.height = h;
  for (auto [u, v] : uv) {
    Keypoint k;
    k.u = u;
    k.v = v;
    k.depth = 123.f;  // must be overwritten
    fs.keypoints.push_back(k);
  }
  return fs;
}
}  // namespace

TEST(RgbdDepth, ValidityChecks) {
  const int W = 160, H = 120;
  cv::Mat d(H, W, CV_32F, cv::Scalar(2.0f));
  d(cv::Rect(80, 0, 80, 60)).setTo(4.0f);                     // step edge at x = 80, y < 60
  d(cv::Rect(0, 100, 20, 20)).setTo(0.0f);                    // hole
  d.at<float>(50, 30) = std::numeric_limits<float>::quiet_NaN();
  d(cv::Rect(120, 90, 30, 20)).setTo(20.0f);                  // too far
  auto fs = featuresAt({{40.2f, 30.4f},    // plane 2 m
                        {100.f, 20.f},     // step top 4 m
                        {80.4f, 20.f},     // on the edge (window straddles) -> reject
                        {10.f, 110.f},     // hole -> reject
                        {31.f, 50.f},      // NaN neighbour -> reject
                        {135.f, 100.f},    // 20 m > max -> reject
                        {0.2f, 60.f}},     // window leaves the image -> reject
                       W, H);
  auto n = assignDepthFromImage(d, RgbdDepthParams(), &fs);
  ASSERT_TRUE(n.ok()) << n.error();
  EXPECT_EQ(*n, 2);
  EXPECT_FLOAT_EQ(fs.keypoints[0].depth, 2.0f);
  EXPECT_FLOAT_EQ(fs.keypoints[1].depth, 4.0f);
  for (int i = 2; i < 7; ++i) EXPECT_EQ(fs.keypoints[i].depth, 0.f) << "keypoint " << i;
}

TEST(RgbdDepth, ConversionAndErrors) {
  cv::Mat raw(10, 10, CV_16U, cv::Scalar(10000));
  raw.at<uint16_t>(3, 3) = 0;
  auto m = depthToMetres(raw, 5000.0);
  ASSERT_TRUE(m.ok());
  EXPECT_FLOAT_EQ(m->at<float>(0, 0), 2.0f);
  EXPECT_FLOAT_EQ(m->at<float>(3, 3), 0.0f);
  EXPECT_FALSE(depthToMetres(raw, 0.0).ok());
  EXPECT_FALSE(depthToMetres(cv::Mat(4, 4, CV_8U), 1.0).ok());

  auto fs = featuresAt({{5, 5}}, 10, 10);
  auto wrong_type = assignDepthFromImage(raw, RgbdDepthParams(), &fs);
  ASSERT_FALSE(wrong_type.ok());
  EXPECT_NE(wrong_type.error().find("CV_32FC1"), std::string::npos);
  auto wrong_size = assignDepthFromImage(cv::Mat(8, 10, CV_32F, cv::Scalar(1)),
                                         RgbdDepthParams(), &fs);
  ASSERT_FALSE(wrong_size.ok());
  EXPECT_NE(wrong_size.error().find("10x8"), std::string::npos);
}
