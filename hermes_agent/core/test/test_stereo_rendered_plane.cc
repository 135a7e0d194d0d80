// End-to-end stereo geometry on rendered images: a textured wall at a known
// distance rendered through the real (distorted) EuRoC stereo rig, rectified,
// ORB-extracted and stereo-matched must give the wall's true depth. This checks
// renderer ground truth, calibration, rectification and sub-pixel matching together.
#include <gtest/gtest.h>

#include <algorithm>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "hermes/agent/orb_extractor.h"
#include "hermes/agent/stereo_matcher.h"
#include "hermes/core/render/raycaster.h"
#include "hermes/core/render/rig.h"
#include "hermes/core/render/scene.h"
#include "hermes/core/stereo_rig.h"

using namespace hermes;
using namespace hermes::render;

namespace {
/// 12 m room; wall x = +6 carries a photograph (or procedural noise), others grey.
Scene photoWallRoom() {
  Scene s;
  s.texel_m = 1.0 / 200.0;
  s.room.kind = "room";
  s.room.lo = Vec3(-6, -6, -6);
  s.room.hi = Vec3(6, 6, 6);
  cv::Mat photo = cv::imread("/usr/share/doc/opencv-doc/examples/data/graf1.png", cv::IMREAD_GRAYSCALE);
  if (photo.empty()) {  // opencv-doc missing: deterministic multi-scale noise
    photo = cv::Mat(600, 800, CV_8U);
    cv::RNG rng(3);
    rng.fill(photo, cv::RNG::UNIFORM, 0, 255);
    cv::GaussianBlur(photo, photo, cv::Size(0, 0), 2.0);
  }
  cv::Mat wall;
  cv::resize(photo, wall, cv::Size(2400, 2400), 0, 0, cv::INTER_CUBIC);
  s.textures.push_back(MipTexture::fromImage(cv::Mat(8, 8, CV_8U, cv::Scalar(128))));
  s.textures.push_back(MipTexture::fromImage(wall));
  s.texture_styles = {TextureStyle::kPoor, TextureStyle::kRich};
  s.room.texture = {0, 1, 0, 0, 0, 0};
  return s;
}

cv::Mat toU8(const cv::Mat& f) {
  cv::Mat u;
  f.convertTo(u, CV_8U);
  return u;
}
}  // namespace

TEST(StereoRenderedPlane, RectifiedMatchingGivesTrueDepth) {
  const Scene scene = photoWallRoom();
  StereoRig rig{eurocCam0(), eurocCam1()};
  auto rect = rectify(rig);
  ASSERT_TRUE(rect.ok()) << rect.error();

  // Body pose so that the rectified left camera looks straight at the wall x = +6
  // from 3.5 m (a fronto-parallel plane in the rectified frame), slightly offset.
  Mat3 R_W_Crect;
  R_W_Crect.col(0) = Vec3(0, -1, 0);
  R_W_Crect.col(1) = Vec3(0, 0, -1);
  R_W_Crect.col(2) = Vec3(1, 0, 0);
  const SE3 T_W_Crect(R_W_Crect, Vec3(2.5, 0.3, -0.2));
  const SE3 T_W_B = T_W_Crect * rect->T_B_Crect.inverse();
  const double depth_true = 6.0 - 2.5;

  RenderOutput left, right;
  Raycaster(scene, RayGrid::fromRadtan(rig.left)).render(T_W_B * rig.left.T_B_C, &left);
  Raycaster(scene, RayGrid::fromRadtan(rig.right)).render(T_W_B * rig.right.T_B_C, &right);
  cv::Mat lr, rr;
  rect->rectifyImages(toU8(left.radiance), toU8(right.radiance), &lr, &rr);

  OrbExtractor orb;
  auto fl = orb.extract(lr);
  auto fr = orb.extract(rr);
  ASSERT_TRUE(fl.ok() && fr.ok());
  auto st = matchStereo(&*fl, *fr, rect->K, rect->baseline, StereoParams{});
  ASSERT_TRUE(st.ok()) << st.error();

  const double d_true = rect->disparityAtDepth(depth_true);
  std::vector<double> disp_err, depth_err;
  int gross = 0;
  for (std::size_t i = 0; i < fl->size(); ++i) {
    if (st->disparity[i] <= 0) continue;
    const double e = std::abs(st->disparity[i] - d_true);
    if (e > 1.0) {
      ++gross;
      continue;
    }
    disp_err.push_back(e);
    depth_err.push_back(std::abs(fl->keypoints[i].depth - depth_true));
  }
  ASSERT_GT(disp_err.size(), 200u) << "too few stereo matches on a textured wall";
  auto median = [](std::vector<double> v) {
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v[v.size() / 2];
  };
  const double med_disp = median(disp_err), med_depth = median(depth_err);
  std::printf("rendered plane at %.2f m: true disparity %.3f px, %zu matches (%d gross), "
              "median |disparity error| %.3f px, median |depth error| %.2f mm\n",
              depth_true, d_true, disp_err.size(), gross, med_disp, med_depth * 1e3);
  EXPECT_LT(med_disp, 0.15);
  EXPECT_LT(static_cast<double>(gross), 0.05 * disp_err.size());
}
