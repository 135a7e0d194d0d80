// Renderer geometry: ground truth matches the drawing camera (checker corners
// through the real EuRoC distortion), RGB-D depth is the analytic z, determinism.
#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include "hermes/core/render/raycaster.h"
#include "hermes/core/render/rig.h"
#include "hermes/core/render/scene.h"
#include "hermes/core/render/sensor.h"

using namespace hermes;
using namespace hermes::render;

namespace {
constexpr double kTexel = 1.0 / 256.0;
constexpr double kSquare = 0.5;  // checker square [m]

/// A 10 m cube room; the wall x = +5 (face 1: u along y, v along z) carries a
/// checker of 0.5 m squares aligned with the texel grid, every other face is uniform.
Scene checkerRoom() {
  Scene s;
  s.texel_m = kTexel;
  s.room.kind = "room";
  s.room.lo = Vec3(-5, -5, -5);
  s.room.hi = Vec3(5, 5, 5);
  const int n = static_cast<int>(10.0 / kTexel), sq = static_cast<int>(kSquare / kTexel);
  cv::Mat checker(n, n, CV_8U);
  for (int v = 0; v < n; ++v)
    for (int u = 0; u < n; ++u) checker.at<std::uint8_t>(v, u) = ((u / sq + v / sq) % 2) ? 220 : 30;
  s.textures.push_back(MipTexture::fromImage(cv::Mat(8, 8, CV_8U, cv::Scalar(128))));
  s.textures.push_back(MipTexture::fromImage(checker));
  s.texture_styles = {TextureStyle::kPoor, TextureStyle::kRich};
  s.room.texture = {0, 1, 0, 0, 0, 0};
  return s;
}

/// Camera looking roughly along +x (z_C = +x, x_C = -y, y_C = -z), perturbed.
SE3 lookingAtWall() {
  Mat3 R;
  R.col(0) = Vec3(0, -1, 0);
  R.col(1) = Vec3(0, 0, -1);
  R.col(2) = Vec3(1, 0, 0);
  return SE3(R * expSO3(Vec3(0.08, -0.12, 0.2)), Vec3(1.2, 0.23, -0.17));
}

cv::Mat toU8(const cv::Mat& f) {
  cv::Mat u;
  f.convertTo(u, CV_8U);
  return u;
}
}  // namespace

TEST(RenderGeometry, CheckerCornersMatchRadtanProjection) {
  const Scene scene = checkerRoom();
  const PinholeRadtan cam = eurocCam0();
  Raycaster rc(scene, RayGrid::fromRadtan(cam));
  const SE3 T_W_C = lookingAtWall();
  RenderOutput out;
  rc.render(T_W_C, &out);
  const cv::Mat img = toU8(out.radiance);
  const SE3 T_C_W = T_W_C.inverse();
  std::vector<cv::Point2f> guess;
  std::vector<Vec2> truth;
  double max_r = 0;
  for (double y = -4.5; y <= 4.5; y += kSquare)
    for (double z = -4.5; z <= 4.5; z += kSquare) {
      Vec2 uv;
      if (!cam.project(T_C_W * Vec3(5, y, z), &uv) || !cam.K.inImage(uv, 25)) continue;
      truth.push_back(uv);
      guess.emplace_back(static_cast<float>(std::round(uv.x()) + 1), static_cast<float>(std::round(uv.y()) - 1));
      max_r = std::max(max_r, (uv - Vec2(cam.K.cx, cam.K.cy)).norm());
    }
  ASSERT_GE(truth.size(), 20u);
  EXPECT_GT(max_r, 250.0) << "corners should reach the strongly distorted image border";
  cv::cornerSubPix(img, guess, cv::Size(6, 6), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 100, 1e-4));
  double worst = 0, sum = 0;
  for (std::size_t i = 0; i < truth.size(); ++i) {
    const double e = (Vec2(guess[i].x, guess[i].y) - truth[i]).norm();
    worst = std::max(worst, e);
    sum += e;
  }
  std::printf("checker corners: %zu, mean error %.3f px, max %.3f px\n", truth.size(), sum / truth.size(), worst);
  EXPECT_LT(worst, 0.3);
}

TEST(RenderGeometry, DepthIsAnalyticZOfPlane) {
  const Scene scene = checkerRoom();
  const RgbdCamera cam = defaultRgbd();
  Raycaster rc(scene, RayGrid::fromPinhole(cam.K));
  const SE3 T_W_C = lookingAtWall();
  RenderOutput out;
  rc.render(T_W_C, &out, true, true);
  const Mat3 R = T_W_C.rotation();
  const Vec3 o = T_W_C.translation();
  int checked = 0;
  double worst = 0;
  for (int v = 0; v < cam.K.height; v += 3)
    for (int u = 0; u < cam.K.width; u += 3) {
      if (out.face.at<int>(v, u) != 1) continue;  // room (box 0), face 1 = wall x = +5
      const Vec3 r((u - cam.K.cx) / cam.K.fx, (v - cam.K.cy) / cam.K.fy, 1.0);
      const double z = (5.0 - o.x()) / (R * r).x();
      worst = std::max(worst, std::abs(out.depth.at<float>(v, u) - z));
      ++checked;
    }
  EXPECT_GT(checked, 5000);
  EXPECT_LT(worst, 1e-3);
}

TEST(RenderGeometry, DeterministicForSeed) {
  std::vector<Vec3> pos;
  for (int i = 0; i < 20; ++i) pos.emplace_back(0.1 * i, 0.05 * i, 0.0);
  SceneParams p;
  p.seed = 7;
  p.wall_margin_m = 2.5;
  p.num_objects = 4;
  auto a = buildScene(pos, p), b = buildScene(pos, p);
  p.seed = 8;
  auto c = buildScene(pos, p);
  ASSERT_TRUE(a.ok() && b.ok() && c.ok()) << a.error();
  PinholeRadtan cam = eurocCam0();
  cam.K = scaleIntrinsics(cam.K, 188, 120);
  Mat3 R;
  R.col(0) = Vec3(0, -1, 0);
  R.col(1) = Vec3(0, 0, -1);
  R.col(2) = Vec3(1, 0, 0);
  const SE3 T_W_C(R, Vec3(0.5, 0.2, 0.0));
  auto shot = [&](const Scene& s, std::uint64_t seed) {
    Raycaster rc(s, RayGrid::fromRadtan(cam));
    RenderOutput out;
    rc.render(T_W_C, &out);
    Sensor sensor(SensorParams{}, seed, cam.K.width, cam.K.height);
    return sensor.expose(out.radiance, 1234.5, 0);
  };
  const cv::Mat ia = shot(*a, 7), ib = shot(*b, 7), ic = shot(*c, 8);
  EXPECT_EQ(cv::norm(ia, ib, cv::NORM_INF), 0.0);
  EXPECT_GT(cv::norm(ia, ic, cv::NORM_L1) / ia.total(), 5.0);
  EXPECT_EQ(sceneToJson(*a), sceneToJson(*b));
  EXPECT_NE(sceneToJson(*a), sceneToJson(*c));
}

TEST(RenderGeometry, SensorGainStaysInRangeAndVaries) {
  Sensor s(SensorParams{}, 3, 64, 48);
  double lo = 1e9, hi = 0;
  for (double t = 0; t < 300; t += 0.05) {
    lo = std::min(lo, s.gain(t));
    hi = std::max(hi, s.gain(t));
    // Auto-exposure steps ramp over 0.5 s: no jump above 8 % between 20 Hz frames.
    EXPECT_LT(std::abs(std::log(s.gain(t + 0.05) / s.gain(t))), 0.08) << t;
  }
  EXPECT_GT(lo, 0.55);
  EXPECT_LT(hi, 1.8);
  EXPECT_GT(hi / lo, 1.2);
}

TEST(RenderGeometry, ParamsReadAndValidate) {
  auto c = Config::fromString("render:\n  scene:\n    clearance_m: 0.9\n    num_objects: 5\n"
                              "  sensor:\n    noise_sigma: 3.5\n", "inline");
  ASSERT_TRUE(c.ok()) << c.error();
  SceneParams sp;
  SensorParams sn;
  ASSERT_TRUE(sp.read(*c));
  ASSERT_TRUE(sn.read(*c));
  EXPECT_EQ(sp.clearance_m, 0.9);
  EXPECT_EQ(sp.num_objects, 5);
  EXPECT_EQ(sn.noise_sigma, 3.5);
  ASSERT_TRUE(c->applyOverride("render.scene.clearance_m=5"));
  EXPECT_FALSE(sp.read(*c));  // clearance beyond the wall margin
  ASSERT_TRUE(c->applyOverride("render.sensor.vignetting=1.5"));
  EXPECT_FALSE(sn.read(*c));
  EXPECT_FALSE(buildScene({}, SceneParams{}).ok());
}
