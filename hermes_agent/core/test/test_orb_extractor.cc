#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

#include "frontend_synthetic.h"
#include "hermes/agent/orb_extractor.h"

using namespace hermes;

namespace {

cv::Mat testImage() {
  cv::Mat img = test::loadSampleGrey("building.jpg");
  if (img.empty()) return img;
  cv::Mat out;
  cv::resize(img, out, cv::Size(752, 480), 0, 0, cv::INTER_AREA);
  return out;
}

/// Fraction of occupied cells of a gx x gy grid, and the largest cell share.
std::pair<double, double> spread(const std::vector<cv::Point2f>& pts, int w, int h, int gx,
                                 int gy) {
  std::vector<int> count(gx * gy, 0);
  for (const auto& p : pts)
    count[std::min(gy - 1, int(p.y * gy / h)) * gx + std::min(gx - 1, int(p.x * gx / w))]++;
  int occupied = 0, biggest = 0;
  for (int c : count) {
    occupied += c > 0;
    biggest = std::max(biggest, c);
  }
  return {double(occupied) / count.size(), double(biggest) / std::max<size_t>(1, pts.size())};
}

}  // namespace

TEST(OrbExtractor, BudgetLevelsAndEvenSpread) {
  cv::Mat img = testImage();
  ASSERT_FALSE(img.empty()) << "opencv-doc building.jpg missing";
  OrbParams p;
  OrbExtractor ex(p);
  int sum = 0;
  for (int b : ex.levelBudget()) sum += b;
  EXPECT_EQ(sum, p.num_features);
  EXPECT_GT(ex.levelBudget()[0], ex.levelBudget()[7]);

  auto fs = ex.extract(img);
  ASSERT_TRUE(fs.ok()) << fs.error();
  EXPECT_GE(fs->size(), size_t(0.9 * p.num_features));
  EXPECT_LE(fs->size(), size_t(p.num_features));
  ASSERT_EQ(fs->descriptors.size(), fs->size());
  ASSERT_EQ(fs->angles.size(), fs->size());
  std::vector<int> per_level(p.num_levels, 0);
  std::vector<cv::Point2f> pts;
  for (const auto& k : fs->keypoints) {
    ASSERT_LT(k.octave, p.num_levels);
    per_level[k.octave]++;
    EXPECT_GE(k.u, p.edge_threshold);
    EXPECT_GE(k.v, p.edge_threshold);
    EXPECT_LT(k.u, img.cols - p.edge_threshold);
    EXPECT_LT(k.v, img.rows - p.edge_threshold);
    pts.emplace_back(k.u, k.v);
  }
  for (int l = 0; l < p.num_levels; ++l) EXPECT_GT(per_level[l], 0) << "level " << l;
  for (float a : fs->angles) {
    EXPECT_GE(a, 0.f);
    EXPECT_LT(a, 360.f);
  }

  // Plain cv::ORB with the same budget clusters on the strongest texture.
  auto orb = cv::ORB::create(p.num_features);
  std::vector<cv::KeyPoint> cvk;
  orb->detect(img, cvk);
  std::vector<cv::Point2f> cvpts;
  for (const auto& k : cvk) cvpts.push_back(k.pt);
  auto ours = spread(pts, img.cols, img.rows, 12, 8);
  auto theirs = spread(cvpts, img.cols, img.rows, 12, 8);
  RecordProperty("occupied_ours", std::to_string(ours.first));
  RecordProperty("occupied_cv", std::to_string(theirs.first));
  EXPECT_GE(ours.first, 0.9);
  EXPECT_GT(ours.first, theirs.first);
  EXPECT_LT(ours.second, theirs.second);
}

TEST(OrbExtractor, OrientationAndDescriptorFollowRotation) {
  cv::Mat img = testImage();
  ASSERT_FALSE(img.empty());
  cv::Mat rot;
  cv::rotate(img, rot, cv::ROTATE_90_CLOCKWISE);  // (x, y) -> (H-1-y, x)
  OrbParams p;
  p.num_levels = 1;  // level 0 only: the rotation is exact there
  p.num_features = 800;
  OrbExtractor ex(p);
  auto a = ex.extract(img), b = ex.extract(rot);
  ASSERT_TRUE(a.ok() && b.ok());
  int pairs = 0;
  std::vector<int> dist;
  std::vector<double> angle_err;
  for (size_t i = 0; i < a->size(); ++i) {
    const float xr = img.rows - 1 - a->keypoints[i].v, yr = a->keypoints[i].u;
    for (size_t j = 0; j < b->size(); ++j) {
      if (std::abs(b->keypoints[j].u - xr) > 0.01f || std::abs(b->keypoints[j].v - yr) > 0.01f)
        continue;
      ++pairs;
      // Image rotated clockwise by 90 deg: angles (y down) grow by 90.
      double d = std::fmod(b->angles[j] - a->angles[i] - 90.0 + 720.0, 360.0);
      angle_err.push_back(std::min(d, 360.0 - d));
      dist.push_back(hammingDistance(a->descriptors[i], b->descriptors[j]));
    }
  }
  ASSERT_GT(pairs, 100);
  std::nth_element(angle_err.begin(), angle_err.begin() + pairs / 2, angle_err.end());
  std::nth_element(dist.begin(), dist.begin() + pairs / 2, dist.end());
  EXPECT_LT(angle_err[pairs / 2], 1.0);
  EXPECT_LT(dist[pairs / 2], 20);  // unrelated descriptors are ~128 apart
}

TEST(OrbExtractor, RejectsBadInputAndParams) {
  OrbExtractor ex;
  EXPECT_FALSE(ex.extract(cv::Mat()).ok());
  EXPECT_FALSE(ex.extract(cv::Mat(40, 40, CV_8UC1, cv::Scalar(0))).ok());
  auto e = ex.extract(cv::Mat(100, 100, CV_32FC1, cv::Scalar(0)));
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.error().find("type"), std::string::npos);
  // A flat image has no corners: empty result, no error.
  auto flat = ex.extract(cv::Mat(200, 200, CV_8UC1, cv::Scalar(90)));
  ASSERT_TRUE(flat.ok());
  EXPECT_EQ(flat->size(), 0u);

  OrbParams p;
  auto c = Config::fromString("orb:\n  num_levels: 0\n", "t.yaml");
  ASSERT_TRUE(c.ok());
  EXPECT_FALSE(p.read(*c).ok());
  auto c2 = Config::fromString("orb:\n  num_features: 500\n  scale_factor: 1.3\n", "t.yaml");
  p = OrbParams();
  ASSERT_TRUE(p.read(*c2).ok());
  EXPECT_EQ(p.num_features, 500);
  EXPECT_DOUBLE_EQ(p.scale_factor, 1.3);
}

TEST(OrbExtractor, AdaptiveThresholdReachesLowContrastRegions) {
  cv::Mat img = testImage();
  ASSERT_FALSE(img.empty());
  // Right half at 15 % contrast: its corners mostly score between 7 and 20.
  cv::Mat half = img(cv::Rect(376, 0, 376, 480));
  half.convertTo(half, CV_8U, 0.15, 128 * 0.85);
  auto countRight = [&](const OrbParams& p) {
    auto fs = OrbExtractor(p).extract(img);
    EXPECT_TRUE(fs.ok());
    int n = 0;
    for (const auto& k : fs->keypoints) n += k.u > 400;
    return n;
  };
  OrbParams adaptive;
  OrbParams fixed;
  fixed.fast_min_threshold = fixed.fast_threshold;
  const int a = countRight(adaptive), f = countRight(fixed);
  RecordProperty("right_adaptive", a);
  RecordProperty("right_fixed", f);
  EXPECT_GT(a, adaptive.num_features / 4);
  EXPECT_LT(f, a / 2);
}

TEST(OrbExtractor, UndistortKeypointsInvertsTheLens) {
  PinholeRadtan cam;
  cam.K.fx = 458.654;
  cam.K.fy = 457.296;
  cam.K.cx = 367.215;
  cam.K.cy = 248.375;
  cam.K.width = 752;
  cam.K.height = 480;
  cam.dist = {-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05};  // EuRoC cam0
  FeatureSet fs;
  std::vector<Vec2> truth;
  for (double u = 60; u < 700; u += 90)
    for (double v = 40; v < 450; v += 70) {
      truth.emplace_back(u, v);
      Vec2 d;
      ASSERT_TRUE(cam.project(Vec3((u - cam.K.cx) / cam.K.fx, (v - cam.K.cy) / cam.K.fy, 1.0), &d));
      Keypoint k;
      k.u = float(d.x());
      k.v = float(d.y());
      fs.keypoints.push_back(k);
    }
  undistortKeypoints(cam, cam.K, &fs);
  for (size_t i = 0; i < truth.size(); ++i) {
    EXPECT_NEAR(fs.keypoints[i].u, truth[i].x(), 1e-3);
    EXPECT_NEAR(fs.keypoints[i].v, truth[i].y(), 1e-3);
  }
}

// Keypoints found on coarse levels land on the level-0 corner they belong to:
// the level's pixel centres are mapped as the resampling placed them, so there
// is no bias towards the image origin that grows with the level's scale
// (x * s would be (s - 1) / 2 px off: 0.5 px at level 4, 1.3 px at level 7).
TEST(OrbExtractor, CoarseLevelKeypointsHaveNoOffset) {
  // Bright squares on a dark background; square k covers pixels [a, a + 39],
  // so its corners lie at a - 0.5 and a + 39.5 in pixel-centre coordinates.
  cv::Mat img(480, 752, CV_8U, cv::Scalar(30));
  std::vector<double> edges_x, edges_y;
  for (int a = 40; a + 40 < 752; a += 88) {
    edges_x.push_back(a - 0.5);
    edges_x.push_back(a + 39.5);
  }
  for (int b = 40; b + 40 < 480; b += 88) {
    edges_y.push_back(b - 0.5);
    edges_y.push_back(b + 39.5);
  }
  for (int a = 40; a + 40 < 752; a += 88)
    for (int b = 40; b + 40 < 480; b += 88)
      img(cv::Rect(a, b, 40, 40)).setTo(cv::Scalar(220));
  auto nearest = [](const std::vector<double>& e, double x) {
    double best = e.front();
    for (double v : e)
      if (std::abs(v - x) < std::abs(best - x)) best = v;
    return best;
  };
  OrbParams p;
  p.num_features = 2000;
  const auto fs = OrbExtractor(p).extract(img);
  ASSERT_TRUE(fs.ok()) << fs.error();
  double sum_x = 0, sum_y = 0;
  int n = 0;
  for (const auto& k : fs->keypoints) {
    if (k.octave < 4) continue;
    sum_x += k.u - nearest(edges_x, k.u);
    sum_y += k.v - nearest(edges_y, k.v);
    ++n;
  }
  ASSERT_GE(n, 20) << "too few coarse-level corners to judge";
  // Inside/outside placement of FAST cancels over the four corners of a square.
  EXPECT_LT(std::abs(sum_x / n), 0.3) << "mean x offset on levels >= 4";
  EXPECT_LT(std::abs(sum_y / n), 0.3) << "mean y offset on levels >= 4";
  // toLevel inverts toBase on every level.
  for (int l = 0; l < p.num_levels; ++l) {
    const cv::Point2d b = fs->toBase(l, 17.25, 33.5);
    const cv::Point2d back = fs->toLevel(l, b.x, b.y);
    EXPECT_NEAR(back.x, 17.25, 1e-9);
    EXPECT_NEAR(back.y, 33.5, 1e-9);
  }
}
