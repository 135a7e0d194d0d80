#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <random>
#include <vector>

#include <opencv2/features2d.hpp>

#include "hermes/core/euroc_dataset.h"
#include "hermes/core/stereo_rig.h"

using namespace hermes;

namespace {

const std::string kMicro = std::string(HERMES_DATA_DIR) + "/euroc_V1_01_micro";

StereoRig microRig() {
  auto l = readEurocCameraYaml(kMicro + "/mav0/cam0/sensor.yaml");
  auto r = readEurocCameraYaml(kMicro + "/mav0/cam1/sensor.yaml");
  HERMES_CHECK(l.ok() && r.ok(), "micro calibration must load");
  return StereoRig{*l, *r};
}

double median(std::vector<double> v) {
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

}  // namespace

TEST(StereoRig, RealEurocBaselineAndPose) {
  const StereoRig rig = microRig();
  auto rs = rectify(rig);
  ASSERT_TRUE(rs.ok()) << rs.error();
  // EuRoC's VI-sensor baseline is about 11 cm.
  EXPECT_NEAR(rs->baseline, rig.T_Cl_Cr().translation().norm(), 1e-9);
  EXPECT_NEAR(rs->baseline, 0.110, 0.002);
  EXPECT_GT(rs->K.fx, 300);
  EXPECT_EQ(rs->K.width, 752);
  EXPECT_EQ(rs->K.height, 480);
  // The rectified frames differ from the originals by small rotations only.
  EXPECT_LT(rotationAngle(rs->R_rect_left), 0.05);
  EXPECT_LT(rotationAngle(rs->R_rect_right), 0.05);
  // Rectified right camera = rectified left shifted by +b along x, same orientation:
  // T_Crect_Crectright = R1 * T_Cl_Cr * R2^T must be (I, (b,0,0)).
  const SE3 T_rl_rr = SE3(rs->R_rect_left, Vec3::Zero()) * rig.T_Cl_Cr() *
                      SE3(Mat3(rs->R_rect_right.transpose()), Vec3::Zero());
  EXPECT_LT(rotationAngle(T_rl_rr.rotation()), 1e-9);
  EXPECT_LT((T_rl_rr.translation() - Vec3(rs->baseline, 0, 0)).norm(), 1e-9);
  // T_B_Crect maps a rectified-left point to the same body point as the original left.
  const Vec3 p_Cl(0.3, -0.2, 2.0);
  const Vec3 p_rect = rs->R_rect_left * p_Cl;
  EXPECT_LT((rs->T_B_Crect * p_rect - rig.left.T_B_C * p_Cl).norm(), 1e-12);
}

TEST(StereoRig, RectifiedPointsShareRowsAndDisparityMatchesDepth) {
  const StereoRig rig = microRig();
  auto rs = rectify(rig);
  ASSERT_TRUE(rs.ok()) << rs.error();
  const SE3 T_Cr_Cl = rig.T_Cl_Cr().inverse();
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> ux(-1, 1), uz(0.5, 20.0);
  int used = 0;
  double max_row = 0, max_disp = 0;
  for (int i = 0; i < 20000 && used < 2000; ++i) {
    const double z = uz(rng);
    const Vec3 p_Cl(ux(rng) * 0.8 * z, ux(rng) * 0.55 * z, z);
    Vec2 uvl, uvr;
    if (!rig.left.project(p_Cl, &uvl) || !rig.right.project(T_Cr_Cl * p_Cl, &uvr)) continue;
    if (!rig.left.K.inImage(uvl, 5) || !rig.right.K.inImage(uvr, 5)) continue;
    ++used;
    const Vec2 rl = rs->rectifyPointLeft(uvl);
    const Vec2 rr = rs->rectifyPointRight(uvr);
    const double z_rect = (rs->R_rect_left * p_Cl).z();
    max_row = std::max(max_row, std::abs(rl.y() - rr.y()));
    max_disp = std::max(max_disp, std::abs((rl.x() - rr.x()) - rs->disparityAtDepth(z_rect)));
    // The rectified left pixel is the pinhole projection of the rotated point.
    const Vec2 expect = rs->K.project(rs->R_rect_left * p_Cl);
    ASSERT_LT((rl - expect).norm(), 1e-3) << uvl.transpose();
  }
  ASSERT_GT(used, 1000);
  EXPECT_LT(max_row, 0.05);
  EXPECT_LT(max_disp, 0.05);
  std::printf("[ rectify ] %d points: max row error %.2e px, max disparity error %.2e px\n", used,
              max_row, max_disp);
}

TEST(StereoRig, RemapTablesAgreeWithPointMapping) {
  const StereoRig rig = microRig();
  RectifyOptions opt;
  opt.fixed_point_maps = false;
  auto rs = rectify(rig, opt);
  ASSERT_TRUE(rs.ok()) << rs.error();
  ASSERT_EQ(rs->map_left_x.type(), CV_32FC1);
  double worst = 0;
  for (int v = 0; v < rs->K.height; v += 37) {
    for (int u = 0; u < rs->K.width; u += 41) {
      // The table says where rectified pixel (u,v) samples the raw image;
      // mapping that raw pixel forward must land on (u,v) again.
      const Vec2 raw_l(rs->map_left_x.at<float>(v, u), rs->map_left_y.at<float>(v, u));
      const Vec2 raw_r(rs->map_right_x.at<float>(v, u), rs->map_right_y.at<float>(v, u));
      // alpha = 0: every rectified pixel samples inside the raw image.
      EXPECT_TRUE(rig.left.K.inImage(raw_l, -0.5)) << u << "," << v;
      EXPECT_TRUE(rig.right.K.inImage(raw_r, -0.5)) << u << "," << v;
      worst = std::max(worst, (rs->rectifyPointLeft(raw_l) - Vec2(u, v)).norm());
      worst = std::max(worst, (rs->rectifyPointRight(raw_r) - Vec2(u, v)).norm());
    }
  }
  EXPECT_LT(worst, 0.01);
}

TEST(StereoRig, RectifiesRealImages) {
  auto ds = EurocDataset::open(kMicro);
  ASSERT_TRUE(ds.ok()) << ds.error();
  auto rs = rectify(StereoRig{ds->cam0(), ds->cam1()});
  ASSERT_TRUE(rs.ok()) << rs.error();
  auto f = ds->load(30);
  ASSERT_TRUE(f.ok()) << f.error();
  cv::Mat lr, rr;
  const auto t0 = std::chrono::steady_clock::now();
  rs->rectifyImages(f->left, f->right, &lr, &rr);
  const double ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_EQ(lr.size(), cv::Size(752, 480));
  ASSERT_EQ(rr.size(), cv::Size(752, 480));
  ASSERT_EQ(lr.type(), CV_8UC1);
  cv::Scalar mean, sd;
  cv::meanStdDev(lr, mean, sd);
  EXPECT_GT(sd[0], 20.0);
  // alpha = 0: (almost) no black border.
  EXPECT_LT(lr.total() - cv::countNonZero(lr), lr.total() / 100);
  EXPECT_LT(rr.total() - cv::countNonZero(rr), rr.total() / 100);

  // Real epipolar check: ORB matches between the rectified images lie on the same row.
  auto orb = cv::ORB::create(1500);
  std::vector<cv::KeyPoint> kl, kr, kl0, kr0;
  cv::Mat dl, dr, dl0, dr0;
  orb->detectAndCompute(lr, cv::noArray(), kl, dl);
  orb->detectAndCompute(rr, cv::noArray(), kr, dr);
  cv::BFMatcher bf(cv::NORM_HAMMING, true);
  std::vector<cv::DMatch> m;
  bf.match(dl, dr, m);
  std::vector<double> dy;
  for (const auto& x : m)
    if (x.distance < 40) dy.push_back(std::abs(kl[x.queryIdx].pt.y - kr[x.trainIdx].pt.y));
  ASSERT_GT(dy.size(), 100u);
  const double med_rect = median(dy);
  // Same on the raw images for comparison.
  orb->detectAndCompute(f->left, cv::noArray(), kl0, dl0);
  orb->detectAndCompute(f->right, cv::noArray(), kr0, dr0);
  std::vector<cv::DMatch> m0;
  bf.match(dl0, dr0, m0);
  std::vector<double> dy0;
  for (const auto& x : m0)
    if (x.distance < 40) dy0.push_back(std::abs(kl0[x.queryIdx].pt.y - kr0[x.trainIdx].pt.y));
  ASSERT_GT(dy0.size(), 100u);
  auto within1 = [](const std::vector<double>& v) {
    return static_cast<double>(std::count_if(v.begin(), v.end(), [](double x) { return x <= 1.0; })) /
           v.size();
  };
  // Cross-checked ORB matches still hold some outliers, and keypoints of coarse
  // octaves are quantised, so count the share of matches within one row.
  EXPECT_GT(within1(dy), 0.5);
  EXPECT_LT(within1(dy0), 0.2);  // raw images: rows differ by ~7-14 px
  EXPECT_LT(med_rect, 0.6);
  std::printf("[ rectify ] remap %.2f ms; ORB matches within 1 row: %.0f%% rectified (%zu), "
              "%.0f%% raw (median |dy| %.1f px)\n", ms, 100 * within1(dy), dy.size(),
              100 * within1(dy0), median(dy0));
}

TEST(StereoRig, DegenerateRigsAreErrors) {
  StereoRig rig = microRig();
  rig.right.T_B_C = rig.left.T_B_C;
  EXPECT_FALSE(rectify(rig).ok());
  rig = microRig();
  rig.right.K.width = 640;
  EXPECT_FALSE(rectify(rig).ok());
  rig = microRig();
  std::swap(rig.left, rig.right);  // right camera on the left
  EXPECT_FALSE(rectify(rig).ok());
}
