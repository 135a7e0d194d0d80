// Realism effects of the renderer: motion blur, photon + read noise, dark
// regions, aliasing copies, their settings and determinism.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>

#include "hermes/core/image_stats.h"
#include "hermes/core/render/motion_blur.h"
#include "hermes/core/render/raycaster.h"
#include "hermes/core/render/rig.h"
#include "hermes/core/render/scene.h"
#include "hermes/core/render/settings.h"
#include "hermes/core/render_cache.h"

using namespace hermes;
using namespace hermes::render;

namespace {

/// Camera looking along +x (z_C = +x, x_C = -y, y_C = -z).
Mat3 lookAlongX() {
  Mat3 R;
  R.col(0) = Vec3(0, -1, 0);
  R.col(1) = Vec3(0, 0, -1);
  R.col(2) = Vec3(1, 0, 0);
  return R;
}

std::vector<Vec3> line(int n, double step) {
  std::vector<Vec3> pos;
  for (int i = 0; i < n; ++i) pos.emplace_back(step * i, 0.0, 0.0);
  return pos;
}

PinholeRadtan smallCam() {
  PinholeRadtan cam = eurocCam0();
  cam.K = scaleIntrinsics(cam.K, 188, 120);
  cam.T_B_C = SE3(lookAlongX(), Vec3::Zero());
  return cam;
}

/// Body moving along +y at `speed` m/s and turning about z at `rate` rad/s.
Trajectory moving(double speed, double rate) {
  Trajectory t;
  for (int k = 0; k <= 20; ++k) {
    const double s = 0.05 * k;
    t.push_back({s, SE3(expSO3(Vec3(0, 0, rate * s)), Vec3(0.5, speed * s, 0.0))});
  }
  return t;
}

Expected<Scene> smallScene(const SceneParams& p) { return buildScene(line(20, 0.1), p); }

SceneParams smallParams() {
  SceneParams p;
  p.seed = 5;
  p.wall_margin_m = 2.5;
  p.num_objects = 4;
  return p;
}

/// The small scene, its camera and a sensor with motion blur over `exposure_s`.
class BlurTest : public ::testing::Test {
 protected:
  void SetUp() override {
    auto s = smallScene(smallParams());
    ASSERT_TRUE(s.ok()) << s.error();
    scene = std::move(*s);
    caster = std::make_unique<Raycaster>(scene, RayGrid::fromRadtan(cam));
    sp.motion_blur = true;
  }
  Scene scene;
  const PinholeRadtan cam = smallCam();
  std::unique_ptr<Raycaster> caster;
  SensorParams sp;
};

}  // namespace

TEST_F(BlurTest, BlurIsZeroWhenStaticAndGrowsWithSpeed) {
  const Raycaster& rc = *caster;
  sp.exposure_s = 0.01;
  double last = -1, last_change = 0;
  for (double speed : {0.0, 0.5, 1.0, 2.0}) {
    RenderOutput ro;
    cv::Mat blurred;
    BlurStats b;
    const Trajectory traj = moving(speed, 0.0);
    const cv::Mat& rad = renderExposure(rc, cam.K, traj, cam.T_B_C, 0.5, sp, false, &ro, &blurred, &b);
    if (speed == 0.0) {
      EXPECT_EQ(b.mean_px, 0.0);
      EXPECT_EQ(b.max_px, 0.0);
      EXPECT_EQ(cv::norm(rad, ro.radiance, cv::NORM_INF), 0.0) << "a static camera must not smear";
    } else {
      EXPECT_GT(b.mean_px, 1.5 * last) << speed;
      const double change = cv::norm(rad, ro.radiance, cv::NORM_L1) / rad.total();
      EXPECT_GT(change, last_change) << speed;
      last_change = change;
    }
    last = std::max(b.mean_px, 1e-3);
  }
  // Rotation alone smears by f * rate * exposure at the centre, (1 + x^2) times
  // that in normalised coordinates towards the borders, which the barrel
  // distortion squeezes back in pixels.
  RenderOutput ro;
  cv::Mat blurred;
  BlurStats b;
  renderExposure(rc, cam.K, moving(0.0, 1.0), cam.T_B_C, 0.5, sp, false, &ro, &blurred, &b);
  const double centre = cam.K.fx * 1.0 * 0.01;
  EXPECT_GT(b.mean_px, 0.8 * centre);
  EXPECT_LT(b.mean_px, 1.4 * centre);
}

TEST_F(BlurTest, BlurApproximatesAveragedSubExposureRenders) {
  // The reference: the mean of 16 renders at poses spread over the exposure.
  const Raycaster& rc = *caster;
  sp.exposure_s = 0.02;
  sp.blur_max_taps = 16;
  const Trajectory traj = moving(1.0, 1.5);
  RenderOutput ro;
  cv::Mat blurred;
  BlurStats b;
  const cv::Mat fast = renderExposure(rc, cam.K, traj, cam.T_B_C, 0.5, sp, false, &ro, &blurred, &b).clone();
  const cv::Mat sharp = ro.radiance.clone();
  cv::Mat mean = cv::Mat::zeros(sharp.size(), CV_32F);
  constexpr int kSub = 16;
  for (int k = 0; k < kSub; ++k) {
    SE3 T_W_B;
    ASSERT_TRUE(interpolatePose(traj, 0.5 + sp.exposure_s * ((k + 0.5) / kSub - 0.5), &T_W_B));
    rc.render(T_W_B * cam.T_B_C, &ro);
    mean += ro.radiance / kSub;
  }
  const double err_fast = cv::norm(fast, mean, cv::NORM_L1) / mean.total();
  const double err_sharp = cv::norm(sharp, mean, cv::NORM_L1) / mean.total();
  std::printf("blur %.2f px mean: |fast - averaged| %.3f, |sharp - averaged| %.3f grey levels\n", b.mean_px,
              err_fast, err_sharp);
  EXPECT_GT(b.mean_px, 2.0);
  EXPECT_LT(err_fast, 0.25 * err_sharp);
}

TEST(RenderRealism, NoiseSigmaFollowsReadPlusPhotonModel) {
  SensorParams p;
  p.vignetting = 0;
  p.drift_amplitude = 0;
  p.step_amplitude = 0;
  p.noise_sigma = 1.5;
  p.photon_noise = true;
  p.photon_gain = 0.05;
  Sensor sensor(p, 9, 64, 64);
  std::vector<cv::Mat> a, b;
  for (double level : {30.0, 100.0, 200.0}) {
    const cv::Mat flat(64, 64, CV_32F, cv::Scalar(level));
    std::vector<cv::Mat> pa, pb;
    for (int k = 0; k < 20; ++k) {
      pa.push_back(sensor.expose(flat, 0.05 * (2 * k), 0));
      pb.push_back(sensor.expose(flat, 0.05 * (2 * k + 1), 0));
    }
    const NoiseFit f = temporalNoise(pa, pb);
    // 8-bit quantisation adds 1/12 grey level^2 to the model's variance.
    const double expect = std::sqrt(p.sigmaAt(level) * p.sigmaAt(level) + 1.0 / 12.0);
    EXPECT_NEAR(f.sigma, expect, 0.08 * expect) << level;
    a.insert(a.end(), pa.begin(), pa.end());
    b.insert(b.end(), pb.begin(), pb.end());
  }
  const NoiseFit all = temporalNoise(a, b);
  EXPECT_NEAR(all.photon_gain, p.photon_gain, 0.2 * p.photon_gain);
  EXPECT_NEAR(all.read_var, p.noise_sigma * p.noise_sigma + 1.0 / 12.0, 0.5);
  // Read noise only: sigma does not depend on the level.
  p.photon_noise = false;
  EXPECT_EQ(p.sigmaAt(10), p.sigmaAt(250));
}

TEST(RenderRealism, SameSeedSameBytes) {
  RenderSettings rs;
  applyRealisticPreset(&rs.scene, &rs.sensor);
  rs.scene.wall_margin_m = 2.5;
  rs.scene.num_objects = 4;
  auto shot = [&](std::uint64_t seed) {
    rs.scene.seed = seed;
    auto scene = smallScene(rs.scene);
    EXPECT_TRUE(scene.ok());
    const PinholeRadtan cam = smallCam();
    Raycaster rc(*scene, RayGrid::fromRadtan(cam));
    Sensor sensor(rs.sensor, seed, cam.K.width, cam.K.height);
    RenderOutput ro;
    cv::Mat blurred;
    const Trajectory traj = moving(1.0, 0.5);
    return sensor.expose(renderExposure(rc, cam.K, traj, cam.T_B_C, 0.5, rs.sensor, false, &ro, &blurred), 0.5, 0);
  };
  const cv::Mat a = shot(3), b = shot(3), c = shot(4);
  EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0.0);
  EXPECT_GT(cv::norm(a, c, cv::NORM_L1) / a.total(), 1.0);
}

TEST(RenderRealism, SettingsErrorsNameTheKey) {
  const std::vector<std::pair<std::string, std::string>> bad = {
      {"render.sensor.exposure_s=0.5", "exposure_s"},   {"render.sensor.photon_gain=-1", "photon_gain"},
      {"render.sensor.blur_max_taps=1", "blur_max_taps"}, {"render.scene.dark_level=1.5", "dark_level"},
      {"render.scene.dark_zones=0", "dark_zones"},       {"render.scene.aliasing_copies=99", "aliasing_copies"},
      {"render.sensor.motion_blur=maybe", "motion_blur"}, {"render.sensor.motion_blurr=true", "motion_blurr"},
  };
  for (const auto& [kv, key] : bad) {
    auto s = readRenderSettings(Config(), {kv});
    ASSERT_FALSE(s.ok()) << kv;
    EXPECT_NE(s.error().find(key), std::string::npos) << kv << " -> " << s.error();
  }
  // The preset turns every effect on; single keys still override it.
  auto s = readRenderSettings(Config(), {"render.realistic=true", "render.scene.aliasing=false"});
  ASSERT_TRUE(s.ok()) << s.error();
  EXPECT_TRUE(s->sensor.motion_blur && s->sensor.photon_noise && s->scene.dark_regions && s->scene.moving_objects > 0);
  EXPECT_FALSE(s->scene.aliasing);
  // By default every effect is on; the plain look (what the accuracy tests pin)
  // has every one off.
  auto d = readRenderSettings(Config(), {});
  ASSERT_TRUE(d.ok());
  EXPECT_TRUE(d->realistic && d->sensor.motion_blur && d->sensor.photon_noise && d->scene.dark_regions &&
              d->scene.aliasing && d->scene.grain && d->scene.moving_objects > 0);
  auto p = readRenderSettings(Config(), {kPlainLook});
  ASSERT_TRUE(p.ok());
  EXPECT_FALSE(p->realistic || p->sensor.motion_blur || p->sensor.photon_noise || p->scene.dark_regions ||
               p->scene.aliasing || p->scene.grain || p->scene.moving_objects > 0);
  EXPECT_EQ(p->fingerprint(), RenderSettings{}.fingerprint());
}

TEST(RenderRealism, CacheFingerprintCoversEverySetting) {
  RenderRequest a;
  a.settings = {kPlainLook};
  auto fa = renderFingerprint(a);
  ASSERT_TRUE(fa.ok());
  for (const char* kv : {"render.sensor.exposure_s=0.004", "render.scene.dark_level=0.3",
                                "render.sensor.photon_gain=0.01", "render.realistic=true"}) {
    RenderRequest b;
    b.settings = {kPlainLook, kv};
    auto fb = renderFingerprint(b);
    ASSERT_TRUE(fb.ok()) << fb.error();
    EXPECT_NE(*fa, *fb) << kv;
  }
  EXPECT_TRUE(isPlainLook(a, *fa));
  RenderRequest d;  // no settings: the realistic look
  auto fd = renderFingerprint(d);
  ASSERT_TRUE(fd.ok());
  EXPECT_NE(*fd, *fa);
  EXPECT_FALSE(isPlainLook(d, *fd));
  RenderRequest c;
  c.settings = {"render.sensor.no_such_key=1"};
  EXPECT_FALSE(renderFingerprint(c).ok());
}

TEST(RenderRealism, DarkRegionsDarkenOnlyInsideZones) {
  SceneParams p = smallParams();
  auto lit = smallScene(p);
  p.dark_regions = true;
  p.dark_zones = 1;
  p.dark_radius_m = 2.0;
  p.dark_level = 0.2;
  auto dark = smallScene(p);
  ASSERT_TRUE(lit.ok() && dark.ok());
  ASSERT_EQ(dark->dark_zones.size(), 1u);
  EXPECT_EQ(lit->objects.size(), dark->objects.size());
  const DarkZone& z = dark->dark_zones[0];
  const PinholeRadtan cam = smallCam();
  Raycaster rl(*lit, RayGrid::fromRadtan(cam)), rd(*dark, RayGrid::fromRadtan(cam));
  int inside = 0, outside = 0;
  int changed_out = 0;
  double ratio_in = 0;
  for (double yaw : {0.0, 1.6, 3.1, 4.7}) {  // look around from the zone centre
    const SE3 T_W_C(expSO3(Vec3(0, 0, yaw)) * lookAlongX(), z.centre);
    RenderOutput ol, od;
    rl.render(T_W_C, &ol, true);
    rd.render(T_W_C, &od, true);
    const RayGrid& rays = rl.rays();
    for (int v = 2; v < ol.radiance.rows - 2; ++v)
      for (int u = 2; u < ol.radiance.cols - 2; ++u) {
        const Vec3 X = T_W_C * (ol.depth.at<float>(v, u) * rays.ray(u, v)).cast<double>();
        const double r = (X - z.centre).norm();
        const float l = ol.radiance.at<float>(v, u), d = od.radiance.at<float>(v, u);
        if (l < 20) continue;
        if (r < 0.5 * z.radius_m) ratio_in += d / l, ++inside;
        // Margin: coarse mip levels of far, oblique faces blend texels from ~1 m around.
        if (r > z.radius_m + 1.0) changed_out += std::abs(d - l) > 1.0f, ++outside;
      }
  }
  ASSERT_GT(inside, 100);
  ASSERT_GT(outside, 100);
  EXPECT_LT(ratio_in / inside, 0.6) << "inside a zone the image must be much darker";
  EXPECT_LT(static_cast<double>(changed_out) / outside, 0.01) << "outside every zone the image must not change";
}

TEST(RenderRealism, AliasingCopiesLookExactlyLikeTheirSource) {
  SceneParams p = smallParams();
  p.num_objects = 8;
  p.wall_margin_m = 5.0;
  auto plain = smallScene(p);
  p.aliasing = true;
  p.aliasing_copies = 3;
  auto aliased = smallScene(p);
  ASSERT_TRUE(plain.ok() && aliased.ok());
  const std::size_t n = plain->objects.size();
  ASSERT_GT(aliased->objects.size(), n) << "no copy could be placed";
  for (std::size_t i = 0; i < n; ++i) {  // the original objects stay where they were
    EXPECT_EQ(plain->objects[i].lo, aliased->objects[i].lo);
    EXPECT_EQ(plain->objects[i].texture, aliased->objects[i].texture);
  }
  const SceneBox& copy = aliased->objects[n];
  ASSERT_GE(copy.copy_of, 0);
  const SceneBox& src = aliased->objects[copy.copy_of];
  EXPECT_TRUE((copy.hi - copy.lo).isApprox(src.hi - src.lo));
  EXPECT_NE(copy.lo, src.lo);
  // Seen from the same relative pose, the copy's pixels equal the source's.
  const PinholeRadtan cam = smallCam();
  Raycaster rc(*aliased, RayGrid::fromRadtan(cam));
  const Vec3 front_src(src.lo.x() - 0.6, 0.5 * (src.lo.y() + src.hi.y()), src.lo.z() + 0.3);
  const Vec3 shift = copy.lo - src.lo;
  RenderOutput os, oc;
  rc.render(SE3(lookAlongX(), front_src), &os);
  rc.render(SE3(lookAlongX(), front_src + shift), &oc);
  const int face_src = (copy.copy_of + 1) * 6, face_copy = static_cast<int>(n + 1) * 6;
  int compared = 0;
  double worst = 0;
  for (int v = 0; v < os.radiance.rows; ++v)
    for (int u = 0; u < os.radiance.cols; ++u) {
      if (u < 2 || v < 2 || u + 2 >= os.radiance.cols || v + 2 >= os.radiance.rows) continue;
      const int fs = os.face.at<int>(v, u), fc = oc.face.at<int>(v, u);
      if (fs / 6 != face_src / 6 || fc / 6 != face_copy / 6 || fs % 6 != fc % 6) continue;
      bool interior = true;  // away from silhouettes and face edges (anti-aliased)
      for (int dv = -2; dv <= 2; ++dv)
        for (int du = -2; du <= 2; ++du)
          interior = interior && os.face.at<int>(v + dv, u + du) == fs && oc.face.at<int>(v + dv, u + du) == fc;
      if (!interior) continue;
      worst = std::max(worst, std::abs(static_cast<double>(os.radiance.at<float>(v, u) - oc.radiance.at<float>(v, u))));
      ++compared;
    }
  ASSERT_GT(compared, 500);
  EXPECT_LT(worst, 1.0);
}

TEST(RenderRealism, MoversSlideBackAndForthThroughTheView) {
  SceneParams p = smallParams();
  p.num_objects = 8;
  p.wall_margin_m = 5.0;
  p.moving_objects = 2;
  auto s = smallScene(p);
  ASSERT_TRUE(s.ok()) << s.error();
  ASSERT_FALSE(s->movers.empty()) << "no mover could be placed";
  const MovingObject& m = s->movers[0];
  EXPECT_EQ(m.offsetAt(0.0), Vec3::Zero());
  EXPECT_TRUE(m.offsetAt(0.5 * m.period_s).isApprox(m.to - m.from, 1e-9));
  EXPECT_LT(m.offsetAt(m.period_s * 0.999).norm(), 0.01 * (m.to - m.from).norm());
  EXPECT_NEAR((m.to - m.from).norm() / (0.5 * m.period_s), p.moving_speed_mps, 1e-9);
  // A camera right above the mover's start, looking down: it sees the mover at
  // time 0 and floor (or something else) once the mover has gone.
  const SceneBox& b = s->objects[m.object];
  Mat3 down;
  down.col(0) = Vec3(1, 0, 0);
  down.col(1) = Vec3(0, -1, 0);
  down.col(2) = Vec3(0, 0, -1);
  const Vec3 above(0.5 * (b.lo.x() + b.hi.x()), 0.5 * (b.lo.y() + b.hi.y()), b.hi.z() + 1.0);
  const PinholeRadtan cam = smallCam();
  Raycaster rc(*s, RayGrid::fromRadtan(cam));
  RenderOutput out;
  auto centreBox = [&](double t) {
    rc.placeMovers(t);
    rc.render(SE3(down, above), &out);
    return out.face.at<int>(out.face.rows / 2, out.face.cols / 2) / 6 - 1;
  };
  EXPECT_EQ(centreBox(0.0), m.object);
  EXPECT_NE(centreBox(0.5 * m.period_s), m.object);
  EXPECT_EQ(centreBox(m.period_s), m.object);
  EXPECT_NE(sceneToJson(*s).find("\"movers\""), std::string::npos);
}
