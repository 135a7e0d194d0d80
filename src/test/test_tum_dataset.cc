#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include <opencv2/imgcodecs.hpp>

#include "hermes/core/tum_dataset.h"

using namespace hermes;
namespace fs = std::filesystem;

namespace {

bool contains(const std::string& s, const std::string& part) {
  return s.find(part) != std::string::npos;
}

constexpr int kW = 64, kH = 48;

// Depth PNG value at (u,v) of frame i: known, so metres can be checked exactly.
std::uint16_t depthValue(int i, int u, int v) { return static_cast<std::uint16_t>(2000 + 100 * i + u + v); }

// A tiny TUM folder: 5 rgb frames at ~30 Hz, depth stamps offset by +4 ms, the
// depth of frame 2 missing from the list, one stray depth 0.5 s later.
std::string writeTinyTum(const std::string& name, bool with_yaml = true) {
  const fs::path dir = fs::path(::testing::TempDir()) / ("tum_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir / "rgb");
  fs::create_directories(dir / "depth");
  std::ofstream rgb(dir / "rgb.txt"), depth(dir / "depth.txt");
  rgb << "# color images\n# file: 'tiny'\n# timestamp filename\n";
  depth << "# depth maps\n# timestamp filename\n";
  for (int i = 0; i < 5; ++i) {
    const double t = 100.0 + i / 30.0;
    char name_rgb[64], name_d[64];
    std::snprintf(name_rgb, sizeof(name_rgb), "rgb/%.6f.png", t);
    std::snprintf(name_d, sizeof(name_d), "depth/%.6f.png", t + 0.004);
    cv::Mat img(kH, kW, CV_8UC3, cv::Scalar(10 * i, 20, 30));
    cv::imwrite((dir / name_rgb).string(), img);
    cv::Mat d(kH, kW, CV_16UC1);
    for (int v = 0; v < kH; ++v)
      for (int u = 0; u < kW; ++u) d.at<std::uint16_t>(v, u) = depthValue(i, u, v);
    d.at<std::uint16_t>(0, 0) = 0;  // a hole
    cv::imwrite((dir / name_d).string(), d);
    rgb << std::fixed << t << " " << name_rgb << "\n";
    if (i != 2) depth << std::fixed << t + 0.004 << " " << name_d << "\n";
  }
  cv::Mat stray(kH, kW, CV_16UC1, cv::Scalar(1));
  cv::imwrite((dir / "depth/stray.png").string(), stray);
  depth << "100.700000 depth/stray.png\n";
  Trajectory gt;
  for (int i = 0; i < 20; ++i)
    gt.push_back({99.9 + 0.02 * i, SE3(expSO3(Vec3(0, 0.01 * i, 0)), Vec3(0.1 * i, 0, 0))});
  EXPECT_TRUE(writeTumTrajectory((dir / "groundtruth.txt").string(), gt));
  if (with_yaml) {
    RgbdCamera cam;
    cam.K = PinholeIntrinsics{50.5, 51.0, 31.5, 23.5, kW, kH};
    cam.depth_scale = 1000.0;
    cam.T_B_C = SE3(expSO3(Vec3(0.1, -0.2, 0.3)), Vec3(0.01, 0.02, -0.03));
    EXPECT_TRUE(writeTumCameraYaml((dir / "camera.yaml").string(), cam));
  }
  return dir.string();
}

}  // namespace

TEST(TumDataset, AssociatesLoadsAndScalesDepth) {
  const std::string dir = writeTinyTum("ok");
  auto ds = TumDataset::open(dir);
  ASSERT_TRUE(ds.ok()) << ds.error();
  EXPECT_FALSE(ds->defaultCamera());
  EXPECT_TRUE(ds->warnings().empty());
  ASSERT_EQ(ds->size(), 4u);  // frame 2 has no depth within 20 ms
  EXPECT_EQ(ds->skipped().rgb_unmatched, 1);
  EXPECT_EQ(ds->skipped().depth_unmatched, 1);  // the stray one
  EXPECT_EQ(ds->skipped().rgb_missing_image, 0);
  const int frame_of_pair[4] = {0, 1, 3, 4};
  for (int k = 0; k < 4; ++k) {
    EXPECT_NEAR(ds->pairs()[k].t_rgb, 100.0 + frame_of_pair[k] / 30.0, 1e-6);
    EXPECT_NEAR(ds->pairs()[k].t_depth - ds->pairs()[k].t_rgb, 0.004, 1e-6);
  }
  EXPECT_DOUBLE_EQ(ds->camera().K.fx, 50.5);
  EXPECT_DOUBLE_EQ(ds->camera().depth_scale, 1000.0);
  EXPECT_NEAR(rotationAngle(ds->camera().T_B_C.rotation()), Vec3(0.1, -0.2, 0.3).norm(), 1e-12);
  EXPECT_NEAR(ds->camera().T_B_C.translation().z(), -0.03, 1e-15);
  ASSERT_TRUE(ds->hasGroundTruth());
  EXPECT_EQ(ds->groundTruth().size(), 20u);

  auto f = ds->load(2);  // frame 3 of the lists
  ASSERT_TRUE(f.ok()) << f.error();
  EXPECT_EQ(f->rgb.type(), CV_8UC3);
  EXPECT_EQ(f->gray.type(), CV_8UC1);
  ASSERT_EQ(f->depth_m.type(), CV_32FC1);
  EXPECT_FLOAT_EQ(f->depth_m.at<float>(0, 0), 0.f);
  EXPECT_FLOAT_EQ(f->depth_m.at<float>(10, 20), depthValue(3, 20, 10) / 1000.f);
  EXPECT_EQ(f->stamp_ns, std::llround((100.0 + 3 / 30.0) * 1e6) * 1000);
  EXPECT_EQ(f->rgb.at<cv::Vec3b>(5, 5)[0], 30);  // blue channel = 10 * i

  // Overridden depth scale (e.g. TUM's 5000 per metre).
  TumOptions opt;
  opt.depth_scale = 5000.0;
  auto ds2 = TumDataset::open(dir, opt);
  ASSERT_TRUE(ds2.ok()) << ds2.error();
  auto f2 = ds2->load(0);
  ASSERT_TRUE(f2.ok()) << f2.error();
  EXPECT_FLOAT_EQ(f2->depth_m.at<float>(1, 1), depthValue(0, 1, 1) / 5000.f);
}

TEST(TumDataset, ToleranceIsConfigurable) {
  const std::string dir = writeTinyTum("tol");
  TumOptions opt;
  opt.max_dt = 0.003;  // the 4 ms offset no longer associates
  auto ds = TumDataset::open(dir, opt);
  ASSERT_FALSE(ds.ok());
  EXPECT_TRUE(contains(ds.error(), dir)) << ds.error();
  opt.max_dt = 0.005;
  ds = TumDataset::open(dir, opt);
  ASSERT_TRUE(ds.ok()) << ds.error();
  EXPECT_EQ(ds->size(), 4u);
  opt.max_dt = 0.04;  // now rgb 2 (t=100.0667) reaches depth 1 or 3 but they are taken
  ds = TumDataset::open(dir, opt);
  ASSERT_TRUE(ds.ok()) << ds.error();
  EXPECT_EQ(ds->size(), 4u);
}

TEST(TumDataset, AssociationIsOneToOneClosestFirst) {
  // a[1] is closest to b[1]; a[0] must then not steal b[1] even though it is in range.
  const std::vector<double> a = {1.00, 1.03, 1.20};
  const std::vector<double> b = {0.96, 1.025, 1.05, 1.5};
  const auto m = associateStamps(a, b, 0.06);
  ASSERT_EQ(m.size(), 2u);
  EXPECT_EQ(m[0], std::make_pair(std::size_t{0}, std::size_t{0}));  // b[1] was taken by a[1]
  EXPECT_EQ(m[1], std::make_pair(std::size_t{1}, std::size_t{1}));
  EXPECT_TRUE(associateStamps(a, {}, 0.1).empty());
}

TEST(TumDataset, FallsBackToIclNuimIntrinsicsWithWarning) {
  const std::string dir = writeTinyTum("noyaml", false);
  auto ds = TumDataset::open(dir);
  ASSERT_TRUE(ds.ok()) << ds.error();
  EXPECT_TRUE(ds->defaultCamera());
  ASSERT_EQ(ds->warnings().size(), 1u);
  EXPECT_TRUE(contains(ds->warnings()[0], "ICL-NUIM")) << ds->warnings()[0];
  EXPECT_DOUBLE_EQ(ds->camera().K.fx, 481.20);
  EXPECT_DOUBLE_EQ(ds->camera().K.fy, 480.00);
  EXPECT_DOUBLE_EQ(ds->camera().K.cx, 319.5);
  EXPECT_DOUBLE_EQ(ds->camera().depth_scale, 5000.0);
  EXPECT_EQ(ds->camera().K.width, 640);
  // Our 64x48 images do not fit the 640x480 default: a named error, not a crash.
  auto f = ds->load(0);
  ASSERT_FALSE(f.ok());
  EXPECT_TRUE(contains(f.error(), dir)) << f.error();
}

TEST(TumDataset, ErrorsNameFilesAndLines) {
  auto r = TumDataset::open("/no/such/tum");
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.error(), "/no/such/tum")) << r.error();

  std::string dir = writeTinyTum("nodepth");
  fs::remove(fs::path(dir) / "depth.txt");
  r = TumDataset::open(dir);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.error(), dir + "/depth.txt")) << r.error();

  dir = writeTinyTum("badline");
  std::ofstream(fs::path(dir) / "rgb.txt", std::ios::app) << "100.9 rgb/x.png extra\n";
  r = TumDataset::open(dir);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.error(), dir + "/rgb.txt:9")) << r.error();

  dir = writeTinyTum("badyaml");
  std::ofstream(fs::path(dir) / "camera.yaml") << "fx: 500\nfy: abc\ncx: 1\ncy: 1\n";
  r = TumDataset::open(dir);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.error(), dir + "/camera.yaml:2")) << r.error();
  std::ofstream(fs::path(dir) / "camera.yaml") << "%YAML:1.0\nfx: 500\nfy: 500\ncx: 1\ncy: 1\nwidth: 64\n";
  r = TumDataset::open(dir);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.error(), "height")) << r.error();

  dir = writeTinyTum("badgt");
  std::ofstream(fs::path(dir) / "groundtruth.txt", std::ios::app) << "1 2 3\n";
  r = TumDataset::open(dir);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.error(), dir + "/groundtruth.txt:22")) << r.error();

  dir = writeTinyTum("8bitdepth");
  auto ok = TumDataset::open(dir);
  ASSERT_TRUE(ok.ok()) << ok.error();
  cv::imwrite(ok->pairs()[1].depth_path, cv::Mat(kH, kW, CV_8UC1, cv::Scalar(7)));
  auto f = ok->load(1);
  ASSERT_FALSE(f.ok());
  EXPECT_TRUE(contains(f.error(), ok->pairs()[1].depth_path)) << f.error();
  EXPECT_TRUE(ok->load(0).ok());
}

TEST(TumDataset, CameraYamlRoundTrip) {
  RgbdCamera cam = iclNuimDefaultCamera();
  cam.T_B_C = SE3(expSO3(Vec3(-0.3, 0.2, 0.05)), Vec3(1, 2, 3));
  cam.rate_hz = 15;
  const std::string path = ::testing::TempDir() + "/rt_camera.yaml";
  ASSERT_TRUE(writeTumCameraYaml(path, cam));
  auto back = readTumCameraYaml(path);
  ASSERT_TRUE(back.ok()) << back.error();
  EXPECT_DOUBLE_EQ(back->K.fx, 481.20);
  EXPECT_DOUBLE_EQ(back->K.cy, 239.5);
  EXPECT_EQ(back->K.height, 480);
  EXPECT_DOUBLE_EQ(back->rate_hz, 15.0);
  EXPECT_LT((back->T_B_C.matrix() - cam.T_B_C.matrix()).norm(), 1e-14);
}

TEST(TumDataset, CameraYamlCarriesColourDistortion) {
  // Old files (no k1..k3) read as undistorted.
  const std::string dir = writeTinyTum("distortion");
  auto plain = TumDataset::open(dir);
  ASSERT_TRUE(plain.ok()) << plain.error();
  EXPECT_FALSE(plain->camera().hasDistortion());

  // k1 k2 p1 p2 k3 (plumb_bob) are read, exposed and written back.
  std::ofstream(fs::path(dir) / "camera.yaml", std::ios::app)
      << "k1: 0.262383\nk2: -0.953104\np1: -0.005358\np2: 0.002628\nk3: 1.163314\n";
  auto ds = TumDataset::open(dir);
  ASSERT_TRUE(ds.ok()) << ds.error();
  const std::array<double, 5> fr1{0.262383, -0.953104, -0.005358, 0.002628, 1.163314};
  EXPECT_EQ(ds->camera().dist, fr1);
  EXPECT_EQ(ds->camera().colourCamera().distortionCount(), 5);
  const std::string path = ::testing::TempDir() + "/rt_camera_dist.yaml";
  ASSERT_TRUE(writeTumCameraYaml(path, ds->camera()));
  auto back = readTumCameraYaml(path);
  ASSERT_TRUE(back.ok()) << back.error();
  EXPECT_EQ(back->dist, fr1);
  {
    std::ifstream in(fs::path(dir) / "camera.yaml");
    std::string text((std::istreambuf_iterator<char>(in)), {});
    text.replace(text.find("k3: 1.163314"), 12, "k3: abc");
    std::ofstream(fs::path(dir) / "camera.yaml") << text;
  }
  auto bad = TumDataset::open(dir);
  ASSERT_FALSE(bad.ok());
  EXPECT_TRUE(contains(bad.error(), "'k3'")) << bad.error();

  // A Hermes camera file copied in as camera.yaml (config/cameras/tum_fr1.yaml).
  fs::copy_file(std::string(HERMES_SOURCE_DIR) + "/config/cameras/tum_fr1.yaml",
                fs::path(dir) / "camera.yaml", fs::copy_options::overwrite_existing);
  auto hermes = TumDataset::open(dir);
  ASSERT_TRUE(hermes.ok()) << hermes.error();
  EXPECT_EQ(hermes->camera().K.fx, 517.306408);
  EXPECT_EQ(hermes->camera().dist, fr1);
  EXPECT_EQ(hermes->camera().depth_scale, 5000.0);
  fs::copy_file(std::string(HERMES_SOURCE_DIR) + "/config/cameras/euroc.yaml",
                fs::path(dir) / "camera.yaml", fs::copy_options::overwrite_existing);
  auto stereo = TumDataset::open(dir);
  ASSERT_FALSE(stereo.ok());
  EXPECT_TRUE(contains(stereo.error(), "'kind'")) << stereo.error();
}
