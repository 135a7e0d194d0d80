#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>

#include <opencv2/calib3d.hpp>

#include "hermes/core/camera_calibration.h"
#include "hermes/core/euroc_dataset.h"
#include "hermes/core/render/rig.h"

using namespace hermes;
namespace fs = std::filesystem;

namespace {

const std::string kCameras = std::string(HERMES_SOURCE_DIR) + "/config/cameras";

bool contains(const std::string& s, const std::string& part) {
  return s.find(part) != std::string::npos;
}

// A fresh folder per test.
std::string testDir() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  const fs::path d = fs::path(::testing::TempDir()) / "camcal" / info->name();
  fs::remove_all(d);
  fs::create_directories(d);
  return d.string();
}

std::string write(const std::string& path, const std::string& text) {
  fs::create_directories(fs::path(path).parent_path());
  std::ofstream(path) << text;
  return path;
}

std::string list(const double* v, int n) {
  std::string s = "[";
  char buf[40];
  for (int i = 0; i < n; ++i) {
    std::snprintf(buf, sizeof(buf), "%.17g", v[i]);
    s += (i ? ", " : "") + std::string(buf);
  }
  return s + "]";
}

std::string rows4(const SE3& T) {  // Kalibr's 4 rows of 4
  const Mat4 M = T.matrix();
  std::string s = "\n";
  for (int r = 0; r < 4; ++r) {
    const double row[4] = {M(r, 0), M(r, 1), M(r, 2), M(r, 3)};
    s += "    - " + list(row, 4) + "\n";
  }
  return s;
}

double rotDiff(const SE3& a, const SE3& b) { return angularDistance(a, b); }

// An equidistant stereo pair (640x480, ~140 deg diagonal field of view, 8 cm
// baseline, small relative rotation). Body = left camera.
StereoRig fisheyeRig() {
  PinholeRadtan l;
  l.model = DistortionModel::kEquidistant;
  l.K = PinholeIntrinsics{331.4, 330.9, 318.7, 243.2, 640, 480};
  l.dist = {-0.0074, 0.0419, -0.0389, 0.0066};
  PinholeRadtan r = l;
  r.K = PinholeIntrinsics{329.8, 329.5, 322.1, 236.8, 640, 480};
  r.dist = {-0.0061, 0.0396, -0.0367, 0.0059};
  r.T_B_C = SE3(expSO3(Vec3(0.004, -0.006, 0.002)), Vec3(0.0801, 0.0003, -0.0002));
  return StereoRig{l, r};
}

// Kalibr camchain text for two cameras (cam1 pose via T_cn_cnm1).
std::string kalibrText(const StereoRig& rig, const std::string& model, const SE3* T_cam_imu) {
  std::string s;
  for (int i = 0; i < 2; ++i) {
    const PinholeRadtan& c = i ? rig.right : rig.left;
    const double intr[4] = {c.K.fx, c.K.fy, c.K.cx, c.K.cy};
    s += "cam" + std::to_string(i) + ":\n";
    if (i == 0 && T_cam_imu) s += "  T_cam_imu:" + rows4(*T_cam_imu);
    if (i == 1) s += "  T_cn_cnm1:" + rows4(rig.T_Cl_Cr().inverse());
    s += "  cam_overlaps: [" + std::to_string(1 - i) + "]\n  camera_model: pinhole\n";
    s += "  distortion_coeffs: " + list(c.dist.data(), 4) + "\n";
    s += "  distortion_model: " + model + "\n  intrinsics: " + list(intr, 4) + "\n";
    s += "  resolution: [" + std::to_string(c.K.width) + ", " + std::to_string(c.K.height) +
         "]\n  rostopic: /cam" + std::to_string(i) + "/image_raw\n";
  }
  return s;
}

// ROS camera_info YAML as camera_calibration_parsers writes it.
std::string cameraInfoText(const std::string& name, const PinholeRadtan& c, const Mat3& R,
                           const Eigen::Matrix<double, 3, 4>& P, int ncoeffs = 5) {
  const double K[9] = {c.K.fx, 0, c.K.cx, 0, c.K.fy, c.K.cy, 0, 0, 1};
  double Rv[9], Pv[12];
  for (int i = 0; i < 9; ++i) Rv[i] = R(i / 3, i % 3);
  for (int i = 0; i < 12; ++i) Pv[i] = P(i / 4, i % 4);
  return "image_width: " + std::to_string(c.K.width) + "\nimage_height: " +
         std::to_string(c.K.height) + "\ncamera_name: " + name +
         "\ncamera_matrix:\n  rows: 3\n  cols: 3\n  data: " + list(K, 9) +
         "\ndistortion_model: plumb_bob\ndistortion_coefficients:\n  rows: 1\n  cols: " +
         std::to_string(ncoeffs) + "\n  data: " + list(c.dist.data(), ncoeffs) +
         "\nrectification_matrix:\n  rows: 3\n  cols: 3\n  data: " + list(Rv, 9) +
         "\nprojection_matrix:\n  rows: 3\n  cols: 4\n  data: " + list(Pv, 12) + "\n";
}

Eigen::Matrix<double, 3, 4> projection(const PinholeIntrinsics& K, double Tx) {
  Eigen::Matrix<double, 3, 4> P;
  P << K.fx, 0, K.cx, Tx, 0, K.fy, K.cy, 0, 0, 0, 1, 0;
  return P;
}

const char* kHermesStereo = R"(# test rig
kind: stereo
resolution: [640, 400]
rate_hz: 25
left:
  model: pinhole
  distortion_model: radtan
  intrinsics: [400, 401, 320, 200]
  distortion: [-0.2, 0.05, 0.001, -0.002]
right:
  model: pinhole
  distortion_model: radtan
  intrinsics: [402, 403, 321, 199]
  distortion: [-0.21, 0.06, 0.0, 0.001]
  T_B_C: [1, 0, 0, 0.12,  0, 1, 0, 0,  0, 0, 1, 0,  0, 0, 0, 1]
)";

const char* kHermesRgbd = R"(kind: rgbd
resolution: [640, 480]
rate_hz: 30
depth_scale: 1000
camera:
  model: pinhole
  distortion_model: plumb_bob
  intrinsics: [525, 526, 319.5, 239.5]
  distortion: [0.1, -0.2, 0.001, 0.002, 0.3]
)";

}  // namespace

// ---------------------------------------------------------------- parsers

TEST(CameraCalibration, EurocSensorYamlPair) {
  const std::string dir = testDir();
  const PinholeRadtan c0 = render::eurocCam0(), c1 = render::eurocCam1();
  fs::create_directories(dir + "/seq/mav0/cam0");
  fs::create_directories(dir + "/seq/mav0/cam1");
  ASSERT_TRUE(writeEurocCameraYaml(dir + "/seq/mav0/cam0/sensor.yaml", c0));
  ASSERT_TRUE(writeEurocCameraYaml(dir + "/seq/mav0/cam1/sensor.yaml", c1));
  for (const std::string& p :
       {dir + "/seq", dir + "/seq/mav0", dir + "/seq/mav0/cam0/sensor.yaml"}) {
    auto c = loadCameraCalibration(p, kCameras);
    ASSERT_TRUE(c.ok()) << p << ": " << c.error();
    EXPECT_EQ(c->format, "euroc");
    EXPECT_EQ(c->kind, CameraCalibration::Kind::kStereo);
    EXPECT_FALSE(c->rectified);
    EXPECT_EQ(c->width, 752);
    EXPECT_EQ(c->height, 480);
    EXPECT_DOUBLE_EQ(c->stereo.left.K.fx, 458.654);
    EXPECT_DOUBLE_EQ(c->stereo.right.dist[0], -0.28368365);
    EXPECT_DOUBLE_EQ(c->stereo.left.rate_hz, 20.0);
    EXPECT_LT((c->stereo.right.T_B_C.matrix() - c1.T_B_C.matrix()).norm(), 1e-12);
    EXPECT_NEAR(c->stereo.T_Cl_Cr().translation().norm(), 0.110, 0.002);
  }
}

TEST(CameraCalibration, KalibrRadtanWithImu) {
  const std::string dir = testDir();
  const StereoRig rig{render::eurocCam0(), render::eurocCam1()};
  const SE3 T_cam_imu = rig.left.T_B_C.inverse();
  const std::string path =
      write(dir + "/camchain-imucam.yaml", kalibrText(rig, "radtan", &T_cam_imu));
  auto c = loadCameraCalibration(path, kCameras);
  ASSERT_TRUE(c.ok()) << c.error();
  EXPECT_EQ(c->format, "kalibr");
  EXPECT_EQ(c->stereo.left.model, DistortionModel::kRadtan);
  EXPECT_DOUBLE_EQ(c->stereo.left.K.cy, 248.375);
  EXPECT_DOUBLE_EQ(c->stereo.right.dist[3], -3.55590700e-05);
  EXPECT_EQ(c->stereo.left.rate_hz, 0.0);  // Kalibr has no rate
  // Body = IMU: T_B_C = T_cam_imu^-1, and cam1 from the chain.
  EXPECT_LT((c->stereo.left.T_B_C.matrix() - rig.left.T_B_C.matrix()).norm(), 1e-9);
  EXPECT_LT((c->stereo.right.T_B_C.matrix() - rig.right.T_B_C.matrix()).norm(), 1e-9);
  EXPECT_TRUE(rectify(c->stereo).ok());
}

TEST(CameraCalibration, KalibrEquidistant) {
  const std::string dir = testDir();
  const StereoRig rig = fisheyeRig();
  const std::string path = write(dir + "/camchain.yaml", kalibrText(rig, "equidistant", nullptr));
  auto c = readKalibrCamchain(path);
  ASSERT_TRUE(c.ok()) << c.error();
  EXPECT_EQ(c->stereo.left.model, DistortionModel::kEquidistant);
  EXPECT_EQ(c->stereo.right.model, DistortionModel::kEquidistant);
  EXPECT_DOUBLE_EQ(c->stereo.right.dist[2], -0.0367);
  EXPECT_EQ(c->stereo.left.distortionCount(), 4);
  EXPECT_EQ(c->width, 640);
  // Body = cam0 without T_cam_imu.
  EXPECT_LT((c->stereo.left.T_B_C.matrix() - Mat4::Identity()).norm(), 1e-15);
  EXPECT_LT((c->stereo.T_Cl_Cr().matrix() - rig.T_Cl_Cr().matrix()).norm(), 1e-9);
}

TEST(CameraCalibration, CameraInfoRawPairRecoversTheRig) {
  // A ROS stereo calibration of raw images: K, D, R, P with the baseline.
  const std::string dir = testDir();
  const StereoRig rig{render::eurocCam0(), render::eurocCam1()};
  auto rs = rectify(rig);
  ASSERT_TRUE(rs.ok()) << rs.error();
  write(dir + "/left.yaml", cameraInfoText("left", rig.left, rs->R_rect_left,
                                           projection(rs->K, 0)));
  write(dir + "/right.yaml", cameraInfoText("right", rig.right, rs->R_rect_right,
                                            projection(rs->K, -rs->K.fx * rs->baseline)));
  for (const std::string& p : {dir, dir + "/left.yaml", dir + "/right.yaml"}) {
    auto c = loadCameraCalibration(p, kCameras);
    ASSERT_TRUE(c.ok()) << p << ": " << c.error();
    EXPECT_EQ(c->format, "camera_info");
    EXPECT_TRUE(c->rectified);
    // The rectified pair of the P matrices.
    EXPECT_DOUBLE_EQ(c->stereo.left.K.fx, rs->K.fx);
    EXPECT_DOUBLE_EQ(c->stereo.right.K.cx, rs->K.cx);
    EXPECT_FALSE(c->stereo.left.hasDistortion());
    EXPECT_NEAR(c->stereo.T_Cl_Cr().translation().x(), rs->baseline, 1e-12);
    // Body = raw left: the rectified left is rotated by R_rect_left^T.
    const SE3 T_Cl_Crect = rig.left.T_B_C.inverse() * rs->T_B_Crect;
    EXPECT_LT(rotDiff(c->stereo.left.T_B_C, T_Cl_Crect), 1e-9);
    // The raw rig: same cameras and extrinsics as the one calibrated.
    ASSERT_TRUE(c->raw_stereo.has_value());
    EXPECT_DOUBLE_EQ(c->raw_stereo->right.dist[1], rig.right.dist[1]);
    EXPECT_LT(rotDiff(c->raw_stereo->T_Cl_Cr(), rig.T_Cl_Cr()), 1e-9);
    EXPECT_LT((c->raw_stereo->T_Cl_Cr().translation() - rig.T_Cl_Cr().translation()).norm(),
              1e-9);
    auto again = rectify(*c->raw_stereo);
    ASSERT_TRUE(again.ok()) << again.error();
    EXPECT_NEAR(again->K.fx, rs->K.fx, 1e-6);
    EXPECT_NEAR(again->baseline, rs->baseline, 1e-9);
  }
}

TEST(CameraCalibration, CameraInfoRectifiedPair) {
  // Images published rectified: no distortion, R = I, P = [K | -fx b].
  const std::string dir = testDir();
  PinholeRadtan cam;
  cam.K = PinholeIntrinsics{700, 700, 640, 360, 1280, 720};
  const Eigen::Matrix<double, 3, 4> Pl = projection(cam.K, 0), Pr = projection(cam.K, -700 * 0.12);
  write(dir + "/zed_left.yaml", cameraInfoText("zed/left", cam, Mat3::Identity(), Pl, 0));
  write(dir + "/zed_right.yaml", cameraInfoText("zed/right", cam, Mat3::Identity(), Pr, 0));
  auto info = readCameraInfoYaml(dir + "/zed_left.yaml");
  ASSERT_TRUE(info.ok()) << info.error();
  EXPECT_EQ(info->camera_name, "zed/left");
  EXPECT_EQ(info->distortion_model, "plumb_bob");
  EXPECT_TRUE(info->D.empty());
  auto c = loadCameraCalibration(dir + "/zed_left.yaml", kCameras);
  ASSERT_TRUE(c.ok()) << c.error();
  EXPECT_TRUE(c->rectified);
  EXPECT_EQ(c->width, 1280);
  EXPECT_DOUBLE_EQ(c->stereo.left.K.fx, 700);
  EXPECT_NEAR(c->stereo.T_Cl_Cr().translation().x(), 0.12, 1e-12);
  EXPECT_LT(c->stereo.left.T_B_C.log().norm(), 1e-12);  // body = left camera
  auto rs = rectify(c->stereo);  // already rectified: rectification changes nothing
  ASSERT_TRUE(rs.ok()) << rs.error();
  EXPECT_LT(rotationAngle(rs->R_rect_left), 1e-9);
  EXPECT_NEAR(rs->baseline, 0.12, 1e-9);
}

TEST(CameraCalibration, CameraInfoPairWithoutBaselineIsAnError) {
  const std::string dir = testDir();
  PinholeRadtan cam;
  cam.K = PinholeIntrinsics{700, 700, 640, 360, 1280, 720};
  cam.dist = {0.1, -0.2, 0, 0, 0.05};
  write(dir + "/left.yaml", cameraInfoText("l", cam, Mat3::Identity(), projection(cam.K, 0)));
  write(dir + "/right.yaml", cameraInfoText("r", cam, Mat3::Identity(), projection(cam.K, 0)));
  auto c = loadCameraCalibration(dir, kCameras);
  ASSERT_FALSE(c.ok());
  EXPECT_TRUE(contains(c.error(), dir + "/right.yaml")) << c.error();
  EXPECT_TRUE(contains(c.error(), "'projection_matrix'")) << c.error();
  EXPECT_TRUE(contains(c.error(), "baseline")) << c.error();
  // Swapped files give a negative baseline.
  write(dir + "/right.yaml", cameraInfoText("r", cam, Mat3::Identity(), projection(cam.K, 70)));
  c = readCameraInfoPair(dir + "/left.yaml", dir + "/right.yaml");
  ASSERT_FALSE(c.ok());
  EXPECT_TRUE(contains(c.error(), "swapped")) << c.error();
}

// The fields of a camera_info message of `cam` (K, D, R, P).
CameraInfoMessage infoMessage(const PinholeRadtan& cam, const Mat3& R,
                              const Eigen::Matrix<double, 3, 4>& P, int n_dist) {
  CameraInfoMessage m;
  m.width = cam.K.width;
  m.height = cam.K.height;
  m.K = {cam.K.fx, 0, cam.K.cx, 0, cam.K.fy, cam.K.cy, 0, 0, 1};
  for (int i = 0; i < 9; ++i) m.R[i] = R(i / 3, i % 3);
  for (int i = 0; i < 12; ++i) m.P[i] = P(i / 4, i % 4);
  m.distortion_model = n_dist > 0 ? "plumb_bob" : "";
  m.D.assign(cam.dist.begin(), cam.dist.begin() + n_dist);
  return m;
}

TEST(CameraCalibration, CameraInfoMessagesAsTheFilesAre) {
  // The raw pair of a ROS stereo calibration as messages on topics: the same
  // calibration as from the files.
  const StereoRig rig{render::eurocCam0(), render::eurocCam1()};
  auto rs = rectify(rig);
  ASSERT_TRUE(rs.ok()) << rs.error();
  auto L = cameraInfoFromMessage(infoMessage(rig.left, rs->R_rect_left, projection(rs->K, 0), 4),
                                 "/cam0/camera_info");
  auto R = cameraInfoFromMessage(
      infoMessage(rig.right, rs->R_rect_right, projection(rs->K, -rs->K.fx * rs->baseline), 4),
      "/cam1/camera_info");
  ASSERT_TRUE(L.ok()) << L.error();
  ASSERT_TRUE(R.ok()) << R.error();
  auto c = stereoFromCameraInfo(*L, *R, "/cam0/camera_info", "/cam1/camera_info");
  ASSERT_TRUE(c.ok()) << c.error();
  EXPECT_TRUE(c->rectified);
  EXPECT_EQ(c->source, "/cam0/camera_info + /cam1/camera_info");
  EXPECT_NEAR(c->stereo.T_Cl_Cr().translation().x(), rs->baseline, 1e-9);
  ASSERT_TRUE(c->raw_stereo.has_value());
  EXPECT_LT(rotDiff(c->raw_stereo->T_Cl_Cr(), rig.T_Cl_Cr()), 1e-9);
  EXPECT_DOUBLE_EQ(c->raw_stereo->left.dist[0], rig.left.dist[0]);

  // An uncalibrated driver: R all zero and no model read as identity, no distortion.
  PinholeRadtan cam;
  cam.K = PinholeIntrinsics{600, 600, 320, 240, 640, 480};
  cam.dist.fill(0);
  CameraInfoMessage m = infoMessage(cam, Mat3::Identity(), projection(cam.K, 0), 0);
  m.R.fill(0);
  auto u = cameraInfoFromMessage(m, "/camera/rgb/camera_info");
  ASSERT_TRUE(u.ok()) << u.error();
  EXPECT_FALSE(u->camera.hasDistortion());

  // Errors name the topic and the field.
  CameraInfoMessage bad = m;
  bad.K.fill(0);  // a driver without calibration
  auto e = cameraInfoFromMessage(bad, "/camera/rgb/camera_info");
  ASSERT_FALSE(e.ok());
  EXPECT_TRUE(contains(e.error(), "/camera/rgb/camera_info")) << e.error();
  EXPECT_TRUE(contains(e.error(), "'camera_matrix'")) << e.error();
  bad = m;
  bad.distortion_model = "plumb_bob";
  bad.D = {0.1, 0.2, 0.3};
  e = cameraInfoFromMessage(bad, "/left/camera_info");
  ASSERT_FALSE(e.ok());
  EXPECT_TRUE(contains(e.error(), "/left/camera_info")) << e.error();
  EXPECT_TRUE(contains(e.error(), "distortion_coefficients")) << e.error();
  bad = m;
  bad.distortion_model = "fisheye_foo";
  bad.D = {0.1, 0.2, 0.3, 0.4};
  e = cameraInfoFromMessage(bad, "/left/camera_info");
  ASSERT_FALSE(e.ok());
  EXPECT_TRUE(contains(e.error(), "'distortion_model'")) << e.error();
}

TEST(CameraCalibration, CalibrationFromCameraInfoTopics) {
  PinholeRadtan cam;
  cam.K = PinholeIntrinsics{700, 700, 640, 360, 1280, 720};
  cam.dist.fill(0);
  const CameraInfoMessage l = infoMessage(cam, Mat3::Identity(), projection(cam.K, 0), 0);
  const CameraInfoMessage r = infoMessage(cam, Mat3::Identity(), projection(cam.K, -700 * 0.05), 0);
  auto st = calibrationFromCameraInfo(l, "/infra1/camera_info", &r, "/infra2/camera_info", 1000);
  ASSERT_TRUE(st.ok()) << st.error();
  EXPECT_EQ(st->kind, CameraCalibration::Kind::kStereo);
  EXPECT_TRUE(st->rectified);
  EXPECT_NEAR(st->stereo.T_Cl_Cr().translation().x(), 0.05, 1e-12);
  auto rgbd = calibrationFromCameraInfo(l, "/color/camera_info", nullptr, "", 1000);
  ASSERT_TRUE(rgbd.ok()) << rgbd.error();
  EXPECT_EQ(rgbd->kind, CameraCalibration::Kind::kRgbd);
  EXPECT_DOUBLE_EQ(rgbd->rgbd.depth_scale, 1000);
  // The right camera's problem is named by its topic.
  CameraInfoMessage bad = r;
  bad.P[3] = 0;  // no baseline
  auto e = calibrationFromCameraInfo(l, "/infra1/camera_info", &bad, "/infra2/camera_info", 1000);
  ASSERT_FALSE(e.ok());
  EXPECT_TRUE(contains(e.error(), "/infra2/camera_info")) << e.error();
  EXPECT_TRUE(contains(e.error(), "baseline")) << e.error();
}

TEST(CameraCalibration, RgbdFromCameraInfoMessage) {
  // TUM fr1's colour camera as a driver would publish it.
  PinholeRadtan cam;
  cam.K = PinholeIntrinsics{517.306408, 516.469215, 318.643040, 255.313989, 640, 480};
  cam.dist = {0.262383, -0.953104, -0.005358, 0.002628, 1.163314, 0, 0, 0};
  auto info = cameraInfoFromMessage(infoMessage(cam, Mat3::Identity(), projection(cam.K, 0), 5),
                                    "/camera/rgb/camera_info");
  ASSERT_TRUE(info.ok()) << info.error();
  auto c = rgbdFromCameraInfo(*info, 5000, "/camera/rgb/camera_info");
  ASSERT_TRUE(c.ok()) << c.error();
  EXPECT_EQ(c->kind, CameraCalibration::Kind::kRgbd);
  EXPECT_DOUBLE_EQ(c->rgbd.K.fx, 517.306408);
  EXPECT_DOUBLE_EQ(c->rgbd.dist[4], 1.163314);
  EXPECT_DOUBLE_EQ(c->rgbd.depth_scale, 5000);
  // Same as the shipped file.
  auto fr1 = loadCameraCalibration("tum_fr1", kCameras);
  ASSERT_TRUE(fr1.ok()) << fr1.error();
  for (int i = 0; i < 5; ++i) EXPECT_DOUBLE_EQ(c->rgbd.dist[i], fr1->rgbd.dist[i]);
  // An equidistant lens is not an RGB-D colour camera; a zero depth scale is refused.
  auto fish = *info;
  fish.camera.model = DistortionModel::kEquidistant;
  fish.distortion_model = "equidistant";
  auto e = rgbdFromCameraInfo(fish, 5000, "/camera/rgb/camera_info");
  ASSERT_FALSE(e.ok());
  EXPECT_TRUE(contains(e.error(), "/camera/rgb/camera_info")) << e.error();
  EXPECT_TRUE(contains(e.error(), "plumb_bob")) << e.error();
  e = rgbdFromCameraInfo(*info, 0, "/camera/rgb/camera_info");
  ASSERT_FALSE(e.ok());
  EXPECT_TRUE(contains(e.error(), "depth scale")) << e.error();
}

TEST(CameraCalibration, TumCameraYamlAndFolder) {
  // What the renderer / a TUM folder holds: camera.yaml with fx .. depth_scale.
  const std::string dir = testDir();
  write(dir + "/seq/camera.yaml",
        "fx: 481.2\nfy: 480.0\ncx: 319.5\ncy: 239.5\nwidth: 640\nheight: 480\n"
        "depth_scale: 5000\nk1: 0.1\nrate_hz: 30\n");
  write(dir + "/seq/rgb.txt", "");
  for (const std::string& p : {dir + "/seq", dir + "/seq/camera.yaml"}) {
    auto c = loadCameraCalibration(p, kCameras);
    ASSERT_TRUE(c.ok()) << p << ": " << c.error();
    EXPECT_EQ(c->kind, CameraCalibration::Kind::kRgbd);
    EXPECT_EQ(c->format, "tum");
    EXPECT_EQ(c->width, 640);
    EXPECT_DOUBLE_EQ(c->rgbd.K.fx, 481.2);
    EXPECT_DOUBLE_EQ(c->rgbd.dist[0], 0.1);
    EXPECT_DOUBLE_EQ(c->rgbd.depth_scale, 5000);
  }
  write(dir + "/bad/camera.yaml", "fx: 481.2\nfy: 480.0\ncx: 319.5\ncy: 239.5\nwidth: 640\n"
                                   "depth_scale: 5000\n");
  auto c = loadCameraCalibration(dir + "/bad", kCameras);
  ASSERT_FALSE(c.ok());
  EXPECT_TRUE(contains(c.error(), dir + "/bad/camera.yaml")) << c.error();
  EXPECT_TRUE(contains(c.error(), "height")) << c.error();
}

TEST(CameraCalibration, HermesStereoAndRgbdRoundTrip) {
  const std::string dir = testDir();
  auto s = loadCameraCalibration(write(dir + "/rig.yaml", kHermesStereo), kCameras);
  ASSERT_TRUE(s.ok()) << s.error();
  EXPECT_EQ(s->format, "hermes");
  EXPECT_EQ(s->width, 640);
  EXPECT_DOUBLE_EQ(s->stereo.right.K.fy, 403);
  EXPECT_DOUBLE_EQ(s->stereo.left.dist[3], -0.002);
  EXPECT_DOUBLE_EQ(s->stereo.right.rate_hz, 25);
  EXPECT_NEAR(s->stereo.T_Cl_Cr().translation().x(), 0.12, 1e-15);
  auto d = loadCameraCalibration(write(dir + "/rgbd.yaml", kHermesRgbd), kCameras);
  ASSERT_TRUE(d.ok()) << d.error();
  EXPECT_EQ(d->kind, CameraCalibration::Kind::kRgbd);
  EXPECT_DOUBLE_EQ(d->rgbd.depth_scale, 1000);
  EXPECT_DOUBLE_EQ(d->rgbd.dist[4], 0.3);
  EXPECT_EQ(d->rgbd.colourCamera().distortionCount(), 5);

  // Write, read back: the same values (full precision).
  for (const auto& [calib, name] : {std::pair{&*s, "s.yaml"}, {&*d, "d.yaml"}}) {
    const std::string p = dir + "/back_" + name;
    ASSERT_TRUE(writeHermesCameraFile(p, *calib, "round trip\nsecond line"));
    auto back = readHermesCameraFile(p);
    ASSERT_TRUE(back.ok()) << back.error();
    EXPECT_EQ(back->kind, calib->kind);
    EXPECT_EQ(back->summary().substr(0, 40), calib->summary().substr(0, 40));
    EXPECT_EQ(back->stereo.right.dist, calib->stereo.right.dist);
    EXPECT_EQ(back->rgbd.dist, calib->rgbd.dist);
    EXPECT_LT((back->stereo.right.T_B_C.matrix() - calib->stereo.right.T_B_C.matrix()).norm(),
              1e-15);
  }
  // An equidistant stereo file round-trips its model too.
  CameraCalibration fe;
  fe.stereo = fisheyeRig();
  fe.width = 640;
  fe.height = 480;
  fe.source = "test";
  ASSERT_TRUE(fe.validate()) << fe.validate().error();
  ASSERT_TRUE(writeHermesCameraFile(dir + "/fe.yaml", fe, "fisheye"));
  auto back = loadCameraCalibration(dir + "/fe.yaml", kCameras);
  ASSERT_TRUE(back.ok()) << back.error();
  EXPECT_EQ(back->stereo.left.model, DistortionModel::kEquidistant);
  EXPECT_EQ(back->stereo.left.dist, fe.stereo.left.dist);
}

// ---------------------------------------------------------------- shipped files

TEST(CameraCalibration, ShippedFilesLoad) {
  int n = 0;
  for (const auto& e : fs::directory_iterator(kCameras)) {
    if (e.path().extension() != ".yaml") continue;
    ++n;
    auto c = loadCameraCalibration(e.path().stem().string(), kCameras);  // by name
    ASSERT_TRUE(c.ok()) << c.error();
    EXPECT_EQ(c->format, "hermes");
    EXPECT_TRUE(c->validate()) << c->validate().error();
    std::ifstream in(e.path());
    std::string first;
    std::getline(in, first);
    EXPECT_EQ(first.rfind("#", 0), 0u) << e.path() << " starts with a comment naming its source";
  }
  EXPECT_GE(n, 5);

  auto fr1 = loadCameraCalibration("tum_fr1", kCameras);
  ASSERT_TRUE(fr1.ok()) << fr1.error();
  EXPECT_EQ(fr1->kind, CameraCalibration::Kind::kRgbd);
  EXPECT_EQ(fr1->rgbd.K.fx, 517.306408);
  EXPECT_EQ(fr1->rgbd.K.fy, 516.469215);
  EXPECT_EQ(fr1->rgbd.K.cx, 318.643040);
  EXPECT_EQ(fr1->rgbd.K.cy, 255.313989);
  const std::array<double, 5> d1{0.262383, -0.953104, -0.005358, 0.002628, 1.163314};
  EXPECT_EQ(fr1->rgbd.dist, d1);
  EXPECT_EQ(fr1->rgbd.depth_scale, 5000.0);
  EXPECT_EQ(fr1->rgbd.rate_hz, 30.0);
  EXPECT_EQ(fr1->width, 640);
  EXPECT_EQ(fr1->height, 480);

  auto fr2 = loadCameraCalibration("tum_fr2", kCameras);
  ASSERT_TRUE(fr2.ok()) << fr2.error();
  EXPECT_EQ(fr2->rgbd.K.fx, 520.908620);
  EXPECT_EQ(fr2->rgbd.dist[4], 0.917205);
  auto fr3 = loadCameraCalibration("tum_fr3", kCameras);
  ASSERT_TRUE(fr3.ok()) << fr3.error();
  EXPECT_EQ(fr3->rgbd.K.fy, 539.2);
  EXPECT_FALSE(fr3->rgbd.hasDistortion());
  auto icl = loadCameraCalibration("icl_nuim", kCameras);
  ASSERT_TRUE(icl.ok()) << icl.error();
  EXPECT_EQ(icl->rgbd.K.fx, 481.20);
  EXPECT_EQ(icl->rgbd.K.fy, 480.00);  // published -480 (y-up renderer), see the file

  // euroc.yaml = the dataset's sensor.yaml pair (and the renderer's copy).
  auto eu = loadCameraCalibration("euroc", kCameras);
  ASSERT_TRUE(eu.ok()) << eu.error();
  StereoRig expect{render::eurocCam0(), render::eurocCam1()};
  const std::string micro = std::string(HERMES_DATA_DIR) + "/euroc_V1_01_micro";
  if (fs::exists(micro)) {
    auto ref = loadCameraCalibration(micro, kCameras);
    ASSERT_TRUE(ref.ok()) << ref.error();
    expect = ref->stereo;
  }
  for (const auto& [a, b] : {std::pair{&eu->stereo.left, &expect.left},
                             {&eu->stereo.right, &expect.right}}) {
    EXPECT_EQ(a->K.fx, b->K.fx);
    EXPECT_EQ(a->K.cy, b->K.cy);
    EXPECT_EQ(a->dist, b->dist);
    EXPECT_LT((a->T_B_C.matrix() - b->T_B_C.matrix()).norm(), 1e-12);
  }
}

// ---------------------------------------------------------------- bad files

TEST(CameraCalibration, BadFilesNameFileAndKey) {
  const std::string dir = testDir();
  auto expectError = [&](const std::string& path, const std::string& key) {
    auto c = loadCameraCalibration(path, kCameras);
    ASSERT_FALSE(c.ok()) << path;
    EXPECT_TRUE(contains(c.error(), path)) << c.error();
    EXPECT_TRUE(contains(c.error(), key)) << c.error();
  };
  auto hermes = [&](const std::string& name, const std::string& from, const std::string& to) {
    std::string t = kHermesStereo;
    const auto at = t.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    return write(dir + "/" + name, t.replace(at, from.size(), to));
  };
  // Missing file, unknown bare name.
  expectError(dir + "/nope.yaml", "does not exist");
  auto nn = loadCameraCalibration("no_such_camera", kCameras);
  ASSERT_FALSE(nn.ok());
  EXPECT_TRUE(contains(nn.error(), kCameras + "/no_such_camera.yaml")) << nn.error();
  EXPECT_TRUE(contains(nn.error(), "tum_fr1")) << nn.error();  // lists what exists
  // Missing key, wrong-length arrays, unknown models, bad values.
  expectError(hermes("nokey.yaml", "  intrinsics: [400, 401, 320, 200]\n", ""),
              "missing key 'left.intrinsics'");
  expectError(hermes("short.yaml", "[400, 401, 320, 200]", "[400, 401, 320]"),
              "key 'left.intrinsics' must be 4 numbers (has 3)");
  expectError(hermes("dist5.yaml", "[-0.21, 0.06, 0.0, 0.001]", "[-0.21, 0.06, 0.0, 0.001, 0]"),
              "key 'right.distortion' must be 4 numbers for distortion_model radtan");
  expectError(hermes("fov.yaml", "distortion_model: radtan", "distortion_model: fov"),
              "key 'left.distortion_model' 'fov' is not supported");
  expectError(hermes("kind.yaml", "kind: stereo", "kind: mono"), "key 'kind' must be");
  expectError(hermes("negfy.yaml", "[400, 401, 320, 200]", "[400, -401, 320, 200]"),
              "key 'left.intrinsics'");
  expectError(hermes("tbc.yaml", "[1, 0, 0, 0.12,", "[2, 0, 0, 0.12,"), "key 'right.T_B_C'");
  expectError(hermes("res.yaml", "[640, 400]", "[640.5, 400]"), "key 'resolution'");
  expectError(hermes("text.yaml", "401, 320", "abc, 320"), "key 'left.intrinsics'");
  // Non-YAML and unknown formats.
  expectError(write(dir + "/junk.yaml", "kind: [stereo\n  : {{\n"), "not valid YAML");
  expectError(write(dir + "/list.yaml", "- 1\n- 2\n"), "not a YAML map");
  expectError(write(dir + "/other.yaml", "foo: 1\n"), "unknown calibration format");

  // Kalibr: unknown camera model, wrong coefficient count, mono chain.
  const StereoRig rig = fisheyeRig();
  std::string k = kalibrText(rig, "radtan", nullptr);
  expectError(write(dir + "/omni.yaml",
                    std::string(k).replace(k.find("camera_model: pinhole"), 21,
                                           "camera_model: omni")),
              "key 'cam0.camera_model' 'omni' is not supported");
  const std::string d4 = list(rig.right.dist.data(), 4);
  expectError(write(dir + "/k5.yaml", std::string(k).replace(k.find(d4), d4.size(),
                                                             "[0.1, 0.2, 0.3, 0.4, 0.5]")),
              "key 'cam1.distortion_coeffs' must be 4 numbers for distortion_model radtan");
  expectError(write(dir + "/mono.yaml", k.substr(0, k.find("cam1:"))), "missing key 'cam1'");
  expectError(write(dir + "/notcn.yaml", std::string(k).replace(k.find("T_cn_cnm1"), 9, "T_xx")),
              "missing key 'cam1.T_cn_cnm1'");

  // camera_info: wrong matrix size, unknown distortion model.
  PinholeRadtan cam;
  cam.K = PinholeIntrinsics{700, 700, 640, 360, 1280, 720};
  const std::string ci = cameraInfoText("c", cam, Mat3::Identity(), projection(cam.K, 0), 0);
  std::string bad = ci;
  bad.replace(bad.find("data: [700, 0, 640"), 18, "data: [700, 640");
  write(dir + "/ci/left.yaml", bad);
  write(dir + "/ci/right.yaml", ci);
  expectError(dir + "/ci/left.yaml", "key 'camera_matrix.data' must be 9 numbers (has 8)");
  bad = ci;
  write(dir + "/ci/left.yaml", bad.replace(bad.find("plumb_bob"), 9, "fisheye"));
  expectError(dir + "/ci/left.yaml", "key 'distortion_model' 'fisheye' is not supported");
  write(dir + "/ci/left.yaml", ci);
  expectError(write(dir + "/ci/single.yaml", ci), "describes one camera");

  // EuRoC sensor.yaml (read by readEurocCameraYaml): a missing key.
  fs::create_directories(dir + "/seq/cam0");
  fs::create_directories(dir + "/seq/cam1");
  ASSERT_TRUE(writeEurocCameraYaml(dir + "/seq/cam0/sensor.yaml", render::eurocCam0()));
  ASSERT_TRUE(writeEurocCameraYaml(dir + "/seq/cam1/sensor.yaml", render::eurocCam1()));
  std::ifstream in(dir + "/seq/cam1/sensor.yaml");
  std::string e((std::istreambuf_iterator<char>(in)), {});
  write(dir + "/seq/cam1/sensor.yaml", e.replace(e.find("intrinsics"), 10, "intrinsix"));
  auto c = loadCameraCalibration(dir + "/seq/cam0/sensor.yaml", kCameras);
  ASSERT_FALSE(c.ok());
  EXPECT_TRUE(contains(c.error(), "cam1/sensor.yaml")) << c.error();
  EXPECT_TRUE(contains(c.error(), "'intrinsics'")) << c.error();
}

// ---------------------------------------------------------------- camera models

TEST(CameraModel, RadtanIsUnchangedAndMatchesOpenCv) {
  const PinholeRadtan cam = render::eurocCam0();
  ASSERT_EQ(cam.distortionCount(), 4);
  for (double x = -0.8; x <= 0.8; x += 0.1)
    for (double y = -0.6; y <= 0.6; y += 0.1) {
      // The radtan formula as it was before the equidistant model: bit-identical.
      const double k1 = cam.dist[0], k2 = cam.dist[1], p1 = cam.dist[2], p2 = cam.dist[3];
      const double r2 = x * x + y * y;
      const double radial = 1.0 + k1 * r2 + k2 * r2 * r2;
      const Vec2 old(x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
                     y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y);
      const Vec2 now = cam.distort(Vec2(x, y));
      EXPECT_EQ(now.x(), old.x());
      EXPECT_EQ(now.y(), old.y());
    }
  // 5 (plumb_bob) and 8 (rational_polynomial) coefficients follow OpenCV.
  for (int n : {5, 8}) {
    PinholeRadtan c = cam;
    c.dist = {-0.28, 0.07, 0.0002, 0.00002, 0.01, 0.002, -0.001, 0.0005};
    for (int i = n; i < 8; ++i) c.dist[i] = 0;
    ASSERT_EQ(c.distortionCount(), n);
    std::vector<cv::Point3d> pts{{0.3, -0.2, 1.0}, {-0.5, 0.4, 1.0}, {0.05, 0.6, 1.0}};
    std::vector<cv::Point2d> uv;
    const cv::Mat K = (cv::Mat_<double>(3, 3) << c.K.fx, 0, c.K.cx, 0, c.K.fy, c.K.cy, 0, 0, 1);
    cv::projectPoints(pts, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), K,
                      cv::Mat(1, n, CV_64F, c.dist.data()), uv);
    for (std::size_t i = 0; i < pts.size(); ++i) {
      Vec2 ours;
      ASSERT_TRUE(c.project(Vec3(pts[i].x, pts[i].y, pts[i].z), &ours));
      EXPECT_NEAR(ours.x(), uv[i].x, 1e-9);
      EXPECT_NEAR(ours.y(), uv[i].y, 1e-9);
      const Vec2 back = c.undistortNormalized(c.distort(Vec2(pts[i].x, pts[i].y)));
      EXPECT_NEAR(back.x(), pts[i].x, 1e-9);
    }
  }
}

TEST(CameraModel, EquidistantRoundTripAndOpenCvFisheye) {
  const PinholeRadtan cam = fisheyeRig().left;
  const cv::Mat K = (cv::Mat_<double>(3, 3) << cam.K.fx, 0, cam.K.cx, 0, cam.K.fy, cam.K.cy, 0,
                     0, 1);
  const cv::Mat D(1, 4, CV_64F, const_cast<double*>(cam.dist.data()));
  double worst = 0;
  // Rays up to 80 degrees off axis, all around.
  for (double th = 0.0; th <= 80.0 * M_PI / 180.0; th += 0.05)
    for (double phi = 0; phi < 2 * M_PI; phi += 0.3) {
      const Vec3 ray(std::sin(th) * std::cos(phi), std::sin(th) * std::sin(phi), std::cos(th));
      const Vec2 xn(ray.x() / ray.z(), ray.y() / ray.z());
      const Vec2 back = cam.undistortNormalized(cam.distort(xn));
      worst = std::max(worst, (back - xn).norm() / std::max(1.0, xn.norm()));
      Vec2 uv;
      ASSERT_TRUE(cam.project(ray, &uv));
      std::vector<cv::Point3d> p{{ray.x(), ray.y(), ray.z()}};
      std::vector<cv::Point2d> cvuv;
      cv::fisheye::projectPoints(p, cvuv, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), K, D);
      EXPECT_NEAR(uv.x(), cvuv[0].x, 1e-6);
      EXPECT_NEAR(uv.y(), cvuv[0].y, 1e-6);
      const Vec2 px = cam.undistortPixel(uv, cam.K);  // pixel of the ideal pinhole
      EXPECT_NEAR(px.x(), cam.K.fx * xn.x() + cam.K.cx, 1e-6 * std::max(1.0, xn.norm()));
    }
  EXPECT_LT(worst, 1e-10);
  EXPECT_EQ(cam.distort(Vec2::Zero()), Vec2::Zero());
}

TEST(CameraModel, EquidistantRectifyGivesHorizontalEpipolarLines) {
  const StereoRig rig = fisheyeRig();
  RectifyOptions opt;
  opt.fixed_point_maps = false;
  auto rs = rectify(rig, opt);
  ASSERT_TRUE(rs.ok()) << rs.error();
  EXPECT_NEAR(rs->baseline, rig.T_Cl_Cr().translation().norm(), 1e-9);
  const SE3 T_Cr_Cl = rig.T_Cl_Cr().inverse();
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1), depth(0.5, 8.0);
  int checked = 0;
  double worst_row = 0, worst_map = 0;
  for (int i = 0; i < 2000; ++i) {
    const Vec3 p_Cl = Vec3(u(rng), u(rng), 1.0).normalized() * depth(rng);
    const Vec3 p_Cr = T_Cr_Cl * p_Cl;
    Vec2 raw_l, raw_r;
    if (!rig.left.project(p_Cl, &raw_l) || !rig.right.project(p_Cr, &raw_r)) continue;
    if (!rig.left.K.inImage(raw_l, 2) || !rig.right.K.inImage(raw_r, 2)) continue;
    // Direct projection into both rectified images, and through the raw pixels.
    const Vec3 pl = rs->R_rect_left * p_Cl, pr = rs->R_rect_right * p_Cr;
    const Vec2 ql = rs->K.project(pl), qr = rs->K.project(pr);
    const Vec2 ul = rs->rectifyPointLeft(raw_l), ur = rs->rectifyPointRight(raw_r);
    worst_row = std::max({worst_row, std::abs(ql.y() - qr.y()), std::abs(ul.y() - ur.y())});
    EXPECT_NEAR(ql.x() - qr.x(), rs->disparityAtDepth(pl.z()), 1e-6);
    EXPECT_NEAR((ul - ql).norm(), 0.0, 1e-6);
    // OpenCV's fisheye remap table agrees with our model: the rectified pixel
    // nearest to ql samples the raw image where our model projects its ray.
    const int c = int(std::lround(ql.x())), r = int(std::lround(ql.y()));
    if (c < 0 || r < 0 || c >= rs->K.width || r >= rs->K.height) continue;
    const Vec3 ray = rs->R_rect_left.transpose() *
                     Vec3((c - rs->K.cx) / rs->K.fx, (r - rs->K.cy) / rs->K.fy, 1.0);
    Vec2 expect;
    ASSERT_TRUE(rig.left.project(ray, &expect));
    const Vec2 table(rs->map_left_x.at<float>(r, c), rs->map_left_y.at<float>(r, c));
    worst_map = std::max(worst_map, (table - expect).norm());
    ++checked;
  }
  EXPECT_GT(checked, 500) << "K " << rs->K.fx << " " << rs->K.fy << " " << rs->K.cx << " "
                          << rs->K.cy << " worst_row " << worst_row;
  EXPECT_LT(worst_row, 0.05);
  EXPECT_LT(worst_map, 0.01);
  // Mixed models are refused.
  StereoRig mixed = rig;
  mixed.right.model = DistortionModel::kRadtan;
  EXPECT_FALSE(rectify(mixed).ok());
}
