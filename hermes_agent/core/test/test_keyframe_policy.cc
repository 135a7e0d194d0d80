#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include <opencv2/imgproc.hpp>

#include "frontend_synthetic.h"
#include "hermes/agent/keyframe_policy.h"

using namespace hermes;

TEST(KeyframePolicy, EntropyOfKnownImages) {
  EXPECT_DOUBLE_EQ(imageEntropy(cv::Mat(64, 64, CV_8UC1, cv::Scalar(77))), 0.0);
  cv::Mat two(64, 64, CV_8UC1, cv::Scalar(10));
  two(cv::Rect(0, 0, 32, 64)).setTo(200);
  EXPECT_NEAR(imageEntropy(two), 1.0, 1e-12);
  cv::Mat four(64, 64, CV_8UC1, cv::Scalar(0));
  four(cv::Rect(0, 0, 16, 64)).setTo(1);
  four(cv::Rect(16, 0, 16, 64)).setTo(2);
  four(cv::Rect(32, 0, 16, 64)).setTo(3);
  EXPECT_NEAR(imageEntropy(four), 2.0, 1e-12);
  cv::Mat noise(512, 512, CV_8UC1);
  cv::RNG rng(4);
  rng.fill(noise, cv::RNG::UNIFORM, 0, 256);
  EXPECT_NEAR(imageEntropy(noise), 8.0, 0.01);
  EXPECT_TRUE(std::isnan(imageEntropy(cv::Mat())));
  EXPECT_TRUE(std::isnan(imageEntropy(cv::Mat(4, 4, CV_32F))));
  // CLAHE keeps a flat image flat and spreads a real photo's histogram.
  KeyframePolicy policy;
  EXPECT_DOUBLE_EQ(policy.claheEntropy(cv::Mat(64, 64, CV_8UC1, cv::Scalar(77))), 0.0);
  cv::Mat photo = test::loadSampleGrey("building.jpg");
  ASSERT_FALSE(photo.empty());
  EXPECT_GT(policy.claheEntropy(photo), imageEntropy(photo) - 0.05);
  EXPECT_GT(policy.claheEntropy(photo), 7.0);
}

namespace {
/// A camera panning over a photo, then over a poorly textured wall.
std::vector<cv::Mat> textureChangeSequence(int rich, int poor) {
  std::vector<cv::Mat> seq;
  cv::Mat photo = test::loadSampleGrey("building.jpg");
  if (photo.empty()) return seq;
  for (int i = 0; i < rich; ++i) seq.push_back(photo(cv::Rect(4 * i, 2 * i, 320, 240)).clone());
  cv::Mat wall(240 + 2 * poor, 320 + 4 * poor, CV_8UC1);
  cv::RNG rng(7);
  rng.fill(wall, cv::RNG::NORMAL, 128, 3);
  cv::GaussianBlur(wall, wall, cv::Size(0, 0), 2.0);
  for (int i = 0; i < poor; ++i) seq.push_back(wall(cv::Rect(4 * i, 2 * i, 320, 240)).clone());
  return seq;
}
}  // namespace

TEST(KeyframePolicy, EntropyRuleFiresWhenTextureChanges) {
  auto seq = textureChangeSequence(15, 8);
  ASSERT_FALSE(seq.empty());
  KeyframePolicyParams p;
  p.max_frames = 1000;  // isolate the entropy rule
  KeyframePolicy entropy(p);
  p.policy = "covisibility";
  KeyframePolicy covis(p);
  TrackingState healthy;
  healthy.tracked = 100;
  healthy.reference_tracked = 100;
  std::vector<int> fired;
  for (size_t i = 0; i < seq.size(); ++i) {
    auto d = entropy.decide(seq[i], healthy);
    if (d.insert) {
      EXPECT_TRUE(d.by_entropy);
      fired.push_back(int(i));
    }
    EXPECT_FALSE(covis.decide(seq[i], healthy).insert) << "frame " << i;
  }
  ASSERT_FALSE(fired.empty());
  EXPECT_EQ(fired.front(), 15) << "first keyframe should be the first poorly textured frame";
  // Once the FIFO has filled with the new texture, the rule goes quiet again.
  EXPECT_LT(fired.back(), 15 + p.entropy_window);

  // The same change while tracking is lost inserts nothing.
  KeyframePolicy lost_policy(KeyframePolicyParams{});
  TrackingState lost = healthy;
  lost.ok = false;
  for (const auto& img : seq) EXPECT_FALSE(lost_policy.decide(img, lost).insert);
}

TEST(KeyframePolicy, CovisibilityRules) {
  KeyframePolicyParams p;
  p.policy = "covisibility";
  p.max_frames = 5;
  KeyframePolicy policy(p);
  TrackingState s;
  s.tracked = 100;
  s.reference_tracked = 100;
  const cv::Mat img(60, 80, CV_8UC1, cv::Scalar(50));
  int inserted = 0;
  for (int i = 1; i <= 10; ++i) {
    auto d = policy.decide(img, s);
    EXPECT_EQ(d.insert, i % 5 == 0) << "frame " << i;
    EXPECT_EQ(d.by_max_frames, i % 5 == 0);
    inserted += d.insert;
  }
  EXPECT_EQ(inserted, 2);
  s.tracked = 85;  // below 0.9 of the reference keyframe's landmarks
  auto d = policy.decide(img, s);
  EXPECT_TRUE(d.insert);
  EXPECT_TRUE(d.by_tracked_ratio);
  s.tracked = 10;  // below min_tracked: tracking not healthy, no keyframe
  EXPECT_FALSE(policy.decide(img, s).insert);
}

TEST(KeyframePolicy, ParamsFromConfig) {
  auto c = Config::fromString("keyframe:\n  policy: covisibility\n  entropy_window: 5\n", "kf.yaml");
  ASSERT_TRUE(c.ok());
  KeyframePolicyParams p;
  ASSERT_TRUE(p.read(*c).ok());
  EXPECT_EQ(p.policy, "covisibility");
  EXPECT_EQ(p.entropy_window, 5);
  EXPECT_TRUE(c->unusedKeys().empty());
  auto bad = Config::fromString("keyframe:\n  policy: magic\n", "kf.yaml");
  KeyframePolicyParams q;
  Status s = q.read(*bad);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().find("keyframe.policy"), std::string::npos);
  ConfigWriter w;
  p.write(&w);
  EXPECT_NE(w.yaml().find("policy: \"covisibility\""), std::string::npos) << w.yaml();
}
