// Renderer scene: encloses the real MH_01 trajectory (clearance, no holes) and
// has rich texture (ORB corners) where meant, poor texture where meant.
#include <gtest/gtest.h>

#include <opencv2/features2d.hpp>

#include "hermes/core/render/raycaster.h"
#include "hermes/core/render/rig.h"
#include "hermes/core/render/scene.h"
#include "hermes/core/render/sensor.h"
#include "hermes/core/trajectory.h"

using namespace hermes;
using namespace hermes::render;

namespace {
const Trajectory& mh01() {
  static const Trajectory t = [] {
    auto r = readTumTrajectory(std::string(HERMES_TRAJECTORY_DIR) + "/MH_01_easy.txt");
    return r.ok() ? *r : Trajectory{};
  }();
  return t;
}

std::vector<Vec3> cameraPositions(const Trajectory& t) {
  std::vector<Vec3> p;
  for (const StampedPose& s : t) {
    p.push_back((s.T_W_B * eurocCam0().T_B_C).translation());
    p.push_back((s.T_W_B * eurocCam1().T_B_C).translation());
  }
  return p;
}

const Scene& mh01Scene() {
  static const Scene s = [] {
    auto r = buildScene(cameraPositions(mh01()), SceneParams{});
    return r.ok() ? *r : Scene{};
  }();
  return s;
}

int orbCorners(const cv::Mat& img) {
  auto orb = cv::ORB::create(20000);
  std::vector<cv::KeyPoint> kps;
  orb->detect(img, kps);
  return static_cast<int>(kps.size());
}
}  // namespace

TEST(RenderScene, EnclosesMh01WithClearanceAndNoHoles) {
  ASSERT_GT(mh01().size(), 1000u) << "MH_01_easy.txt missing under " << HERMES_TRAJECTORY_DIR;
  const Scene& s = mh01Scene();
  ASSERT_GT(s.objects.size(), 3u);
  double worst = 1e9;
  for (const Vec3& p : cameraPositions(mh01())) worst = std::min(worst, clearance(s, p));
  std::printf("min clearance along MH_01: %.3f m, %zu objects\n", worst, s.objects.size());
  EXPECT_GE(worst, 0.7);
  // Walls at least 2.5 m from every camera position.
  for (const Vec3& p : cameraPositions(mh01())) {
    ASSERT_GE((p - s.room.lo).head<2>().minCoeff(), 2.5);
    ASSERT_GE((s.room.hi - p).head<2>().minCoeff(), 2.5);
  }
  PinholeRadtan cam = eurocCam0();
  cam.K = scaleIntrinsics(cam.K, 188, 120);
  Raycaster rc(s, RayGrid::fromRadtan(cam));
  RenderOutput out;
  int frames = 0;
  for (std::size_t i = 0; i < mh01().size(); i += 40, ++frames) {  // every 2 s (20 Hz file)
    rc.render(mh01()[i].T_W_B * cam.T_B_C, &out, true, true);
    double mn, mx;
    cv::minMaxLoc(out.face, &mn, &mx);
    ASSERT_GE(mn, 0) << "hole at pose " << i;
    cv::minMaxLoc(out.depth, &mn, &mx);
    ASSERT_GT(mn, 0.3) << "pose " << i;
    ASSERT_TRUE(std::isfinite(mx)) << "pose " << i;
  }
  EXPECT_GT(frames, 80);
}

TEST(RenderScene, RichAndPoorTexture) {
  ASSERT_GT(mh01().size(), 1000u);
  const Scene& s = mh01Scene();
  const PinholeRadtan cam = eurocCam0();
  Raycaster rc(s, RayGrid::fromRadtan(cam));
  Sensor sensor(SensorParams{}, 1, cam.K.width, cam.K.height);
  RenderOutput out;
  // Typical frames: median ORB count over a few poses of the flight.
  std::vector<int> counts;
  for (double dt : {10.0, 40.0, 80.0, 120.0, 160.0}) {
    SE3 T_W_B;
    ASSERT_TRUE(interpolatePose(mh01(), mh01().front().t + dt, &T_W_B));
    rc.render(T_W_B * cam.T_B_C, &out);
    counts.push_back(orbCorners(sensor.expose(out.radiance, dt, 0)));
  }
  std::sort(counts.begin(), counts.end());
  // Poor view: the same scene with every face near-uniform.
  Scene poor = s;
  for (std::size_t i = 0; i < poor.textures.size(); ++i) {
    const cv::Mat& l0 = s.textures[i].levels[0];
    poor.textures[i] = MipTexture::fromImage(
        synthesizeTexture(l0.cols, l0.rows, s.texel_m, TextureStyle::kPoor, 0, 100 + i, PhotoLibrary{}));
  }
  Raycaster rcp(poor, RayGrid::fromRadtan(cam));
  SE3 T_W_B;
  ASSERT_TRUE(interpolatePose(mh01(), mh01().front().t + 40.0, &T_W_B));
  rcp.render(T_W_B * cam.T_B_C, &out);
  const int poor_count = orbCorners(sensor.expose(out.radiance, 40.0, 0));
  std::printf("ORB corners: typical frames %d..%d (median %d), poor-texture view %d; photos %zu\n",
              counts.front(), counts.back(), counts[2], poor_count, s.photo_names.size());
  EXPECT_GT(counts[2], 500);
  EXPECT_LT(poor_count, counts[2] / 3);
}
