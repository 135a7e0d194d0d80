#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "hermes/agent/camera_input.h"

using namespace hermes;
using namespace hermes::agent;

namespace {

const std::string kCameras = std::string(HERMES_SOURCE_DIR) + "/config/cameras";

CameraCalibration load(const std::string& name) {
  auto c = loadCameraCalibration(name, kCameras);
  HERMES_CHECK(c.ok(), c.error());
  return *c;
}

// A bright Gaussian spot centred on the sub-pixel position uv.
void drawSpot(cv::Mat* img, const Vec2& uv, double sigma = 1.2) {
  const int x0 = int(std::lround(uv.x())), y0 = int(std::lround(uv.y()));
  for (int y = y0 - 4; y <= y0 + 4; ++y)
    for (int x = x0 - 4; x <= x0 + 4; ++x) {
      if (x < 0 || y < 0 || x >= img->cols || y >= img->rows) continue;
      const double r2 = (x - uv.x()) * (x - uv.x()) + (y - uv.y()) * (y - uv.y());
      const double v = 250.0 * std::exp(-r2 / (2 * sigma * sigma));
      img->at<std::uint8_t>(y, x) = std::max(img->at<std::uint8_t>(y, x), std::uint8_t(v));
    }
}

// Intensity-weighted centroids of the connected bright regions.
std::vector<Vec2> findSpots(const cv::Mat& grey) {
  cv::Mat labels, stats, centroids;
  const int n = cv::connectedComponentsWithStats(grey > 20, labels, stats, centroids, 8, CV_32S);
  std::vector<double> sw(n, 0), su(n, 0), sv(n, 0);
  for (int y = 0; y < grey.rows; ++y)
    for (int x = 0; x < grey.cols; ++x) {
      const int l = labels.at<int>(y, x);
      if (l == 0) continue;
      const double w = grey.at<std::uint8_t>(y, x);
      sw[l] += w;
      su[l] += w * x;
      sv[l] += w * y;
    }
  std::vector<Vec2> out;
  for (int l = 1; l < n; ++l) out.emplace_back(su[l] / sw[l], sv[l] / sw[l]);
  return out;
}

Vec2 nearest(const std::vector<Vec2>& spots, const Vec2& uv) {
  Vec2 best(1e9, 1e9);
  for (const Vec2& s : spots)
    if ((s - uv).norm() < (best - uv).norm()) best = s;
  return best;
}

}  // namespace

TEST(CameraInput, RawEurocStereoIsRectified) {
  const CameraCalibration calib = load("euroc");
  auto in = CameraInput::create(calib);
  ASSERT_TRUE(in.ok()) << in.error();
  const AgentCamera cam = in->camera();
  EXPECT_NEAR(cam.baseline, 0.110, 0.002);
  EXPECT_EQ(cam.K.width, 752);
  EXPECT_EQ(cam.K.height, 480);
  EXPECT_EQ(in->syncParams().slop, 0.001);

  // Points seen by the rectified left camera at several depths, drawn where
  // the raw (distorted) cameras see them.
  cv::Mat left(480, 752, CV_8UC1, cv::Scalar(0)), right = left.clone();
  struct Point { Vec3 p_rect; Vec2 uv_left; };
  std::vector<Point> points;
  const double depths[] = {1.5, 2.5, 4.0, 7.0};
  const SE3 T_Cl_Crect = calib.stereo.left.T_B_C.inverse() * cam.T_B_C;
  const SE3 T_Cr_Crect = calib.stereo.right.T_B_C.inverse() * cam.T_B_C;
  int k = 0;
  for (double v = 60.3; v < 440; v += 90)
    for (double u = 90.6; u < 700; u += 110, ++k) {
      const double z = depths[k % 4];
      const Vec3 p((u - cam.K.cx) / cam.K.fx * z, (v - cam.K.cy) / cam.K.fy * z, z);
      Vec2 dl, dr;
      ASSERT_TRUE(calib.stereo.left.project(T_Cl_Crect * p, &dl));
      ASSERT_TRUE(calib.stereo.right.project(T_Cr_Crect * p, &dr));
      drawSpot(&left, dl);
      drawSpot(&right, dr);
      points.push_back({p, Vec2(u, v)});
    }
  auto f = in->stereo(12.5, left, right, "mono8");
  ASSERT_TRUE(f.ok()) << f.error();
  EXPECT_EQ(f->stamp, 12.5);
  ASSERT_EQ(f->left.type(), CV_8UC1);
  ASSERT_EQ(f->right.size(), cv::Size(752, 480));
  const auto sl = findSpots(f->left), sr = findSpots(f->right);
  ASSERT_EQ(sl.size(), points.size());
  ASSERT_EQ(sr.size(), points.size());
  for (const Point& pt : points) {
    const double d = cam.K.fx * cam.baseline / pt.p_rect.z();
    const Vec2 l = nearest(sl, pt.uv_left), r = nearest(sr, pt.uv_left - Vec2(d, 0));
    EXPECT_LT((l - pt.uv_left).norm(), 0.5) << pt.uv_left.transpose();
    EXPECT_NEAR(l.y(), r.y(), 0.5) << pt.uv_left.transpose();
    EXPECT_NEAR(l.x() - r.x(), d, 0.5) << pt.uv_left.transpose() << " z " << pt.p_rect.z();
  }

  // Colour encodings give the grey of mono8.
  cv::Mat l3, r3;
  cv::cvtColor(left, l3, cv::COLOR_GRAY2BGR);
  cv::cvtColor(right, r3, cv::COLOR_GRAY2BGR);
  for (const char* enc : {"bgr8", "rgb8"}) {
    auto g = in->stereo(12.55, l3, r3, enc);
    ASSERT_TRUE(g.ok()) << g.error();
    EXPECT_EQ(cv::norm(g->left, f->left, cv::NORM_INF), 0) << enc;
    EXPECT_EQ(cv::norm(g->right, f->right, cv::NORM_INF), 0) << enc;
  }
  EXPECT_TRUE(in->errorCounts().empty());
  EXPECT_EQ(in->framesConverted(), 3);
}

TEST(CameraInput, ColourChannelOrderFollowsTheEncoding) {
  auto in = CameraInput::create(load("tum_fr3"));
  ASSERT_TRUE(in.ok()) << in.error();
  cv::Mat red(480, 640, CV_8UC3, cv::Scalar(0, 0, 255));  // red in BGR order
  const cv::Mat depth(480, 640, CV_32FC1, cv::Scalar(1.0f));
  auto bgr = in->rgbd(1.0, red, "bgr8", depth, "32FC1");
  auto rgb = in->rgbd(1.1, red, "rgb8", depth, "32FC1");  // the same bytes read as blue
  ASSERT_TRUE(bgr.ok() && rgb.ok());
  EXPECT_NEAR(bgr->left.at<std::uint8_t>(5, 5), 76, 1);  // 0.299 * 255
  EXPECT_NEAR(rgb->left.at<std::uint8_t>(5, 5), 29, 1);  // 0.114 * 255
}

TEST(CameraInput, StereoErrorsNameTheCauseAndAreCounted) {
  auto in = CameraInput::create(load("euroc"));
  ASSERT_TRUE(in.ok());
  const cv::Mat ok(480, 752, CV_8UC1, cv::Scalar(0)), small(480, 640, CV_8UC1, cv::Scalar(0));
  auto e = in->stereo(1.0, small, ok, "mono8");
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.error().find("left image is 640x480 but the calibration says 752x480"),
            std::string::npos) << e.error();
  EXPECT_TRUE(in->lastErrorIsNew());
  e = in->stereo(1.1, ok, small, "mono8");
  EXPECT_NE(e.error().find("right image is 640x480"), std::string::npos) << e.error();
  EXPECT_FALSE(in->lastErrorIsNew());
  e = in->stereo(1.2, ok, ok, "yuv422");
  EXPECT_NE(e.error().find("unsupported encoding 'yuv422' on the left image"), std::string::npos)
      << e.error();
  EXPECT_EQ(in->lastErrorCause(), "unsupported encoding");
  e = in->stereo(1.3, ok, ok, "bgr8");  // a one-channel image labelled bgr8
  EXPECT_NE(e.error().find("'bgr8' needs 3 8-bit channel(s)"), std::string::npos) << e.error();
  e = in->stereo(1.4, cv::Mat(), ok, "mono8");
  EXPECT_NE(e.error().find("left image is empty"), std::string::npos) << e.error();
  e = in->stereo(std::numeric_limits<double>::quiet_NaN(), ok, ok, "mono8");
  EXPECT_FALSE(e.ok());
  const cv::Mat depth(480, 752, CV_32FC1, cv::Scalar(1.0f));
  e = in->rgbd(1.5, ok, "mono8", depth, "32FC1");
  EXPECT_NE(e.error().find("RGB-D images given to the stereo camera"), std::string::npos);
  const auto& n = in->errorCounts();
  EXPECT_EQ(n.at("size mismatch"), 2);
  EXPECT_EQ(n.at("unsupported encoding"), 1);
  EXPECT_EQ(n.at("type does not match encoding"), 1);
  EXPECT_EQ(n.at("empty image"), 1);
  EXPECT_EQ(n.at("bad stamp"), 1);
  EXPECT_EQ(n.at("wrong camera kind"), 1);
  EXPECT_EQ(in->framesConverted(), 0);
}

TEST(CameraInput, RectifiedStereoPassesThroughAndAlignsCx) {
  CameraCalibration c = load("euroc");
  c.rectified = true;
  for (PinholeRadtan* cam : {&c.stereo.left, &c.stereo.right}) {
    cam->dist = {};
    cam->K = c.stereo.left.K;
  }
  c.stereo.right.K.cx = c.stereo.left.K.cx - 3.0;  // disparity at infinity: 3 px
  c.stereo.right.T_B_C = c.stereo.left.T_B_C * SE3(Mat3::Identity(), Vec3(0.12, 0, 0));
  auto in = CameraInput::create(c);
  ASSERT_TRUE(in.ok()) << in.error();
  EXPECT_NEAR(in->camera().baseline, 0.12, 1e-9);
  EXPECT_EQ(in->camera().K.fx, c.stereo.left.K.fx);
  EXPECT_EQ(in->camera().K.cx, c.stereo.left.K.cx);
  cv::Mat l(480, 752, CV_8UC1, cv::Scalar(0)), r = l.clone();
  drawSpot(&l, Vec2(300, 200));
  drawSpot(&r, Vec2(280, 200));  // 20 px disparity + 3 px of cx
  auto f = in->stereo(3.0, l, r, "mono8");
  ASSERT_TRUE(f.ok()) << f.error();
  EXPECT_EQ(cv::norm(f->left, l, cv::NORM_INF), 0);
  const auto sr = findSpots(f->right);
  ASSERT_EQ(sr.size(), 1u);
  EXPECT_NEAR(sr[0].x(), 283.0, 0.05);
  EXPECT_NEAR(sr[0].y(), 200.0, 0.05);

  CameraInputParams p;
  p.stereo_images = "rectified";
  auto bad = CameraInput::create(load("euroc"), p);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().find("raw (distorted) cameras"), std::string::npos) << bad.error();
}

TEST(CameraInput, DepthEncodingsGiveTheSameMetres) {
  auto in = CameraInput::create(load("tum_fr3"));
  ASSERT_TRUE(in.ok());
  EXPECT_EQ(in->depthScale16u(), 5000.0);
  EXPECT_EQ(in->camera().baseline, 0.0);
  EXPECT_EQ(in->syncParams().slop, 0.020);
  const cv::Mat grey(480, 640, CV_8UC1, cv::Scalar(90));
  cv::Mat d16(480, 640, CV_16UC1), d32(480, 640, CV_32FC1);
  for (int y = 0; y < 480; ++y)
    for (int x = 0; x < 640; ++x) {
      d16.at<std::uint16_t>(y, x) = std::uint16_t(5000 + 7 * x + y);  // TUM PNG: 5000 per metre
      d32.at<float>(y, x) = float((5000 + 7 * x + y) / 5000.0);
    }
  auto a = in->rgbd(1.0, grey, "mono8", d16, "16UC1");
  auto b = in->rgbd(1.1, grey, "mono8", d32, "32FC1");
  ASSERT_TRUE(a.ok() && b.ok()) << a.error() << b.error();
  ASSERT_EQ(a->depth.type(), CV_32FC1);
  EXPECT_LT(cv::norm(a->depth, b->depth, cv::NORM_INF), 1e-6);
  // fr3 has no distortion: the images are handed on unchanged.
  EXPECT_EQ(cv::norm(a->left, grey, cv::NORM_INF), 0);
  EXPECT_EQ(cv::norm(b->depth, d32, cv::NORM_INF), 0);

  // A ROS driver's millimetres.
  CameraInputParams p;
  p.depth_scale_16u = 1000;
  auto mm = CameraInput::create(load("tum_fr3"), p);
  ASSERT_TRUE(mm.ok());
  cv::Mat d(480, 640, CV_16UC1, cv::Scalar(1234));
  auto m = mm->rgbd(2.0, grey, "mono8", d, "16UC1");
  ASSERT_TRUE(m.ok());
  EXPECT_FLOAT_EQ(m->depth.at<float>(10, 10), 1.234f);

  // Invalid depth becomes 0.
  cv::Mat bad(480, 640, CV_32FC1, cv::Scalar(2.0f));
  bad.at<float>(1, 1) = std::numeric_limits<float>::quiet_NaN();
  bad.at<float>(1, 2) = std::numeric_limits<float>::infinity();
  bad.at<float>(1, 3) = 0.f;
  bad.at<float>(1, 4) = -1.5f;
  auto z = in->rgbd(3.0, grey, "mono8", bad, "32FC1");
  ASSERT_TRUE(z.ok());
  for (int x = 1; x <= 4; ++x) EXPECT_EQ(z->depth.at<float>(1, x), 0.f) << x;
  EXPECT_EQ(z->depth.at<float>(1, 5), 2.f);

  // Errors.
  auto e = in->rgbd(4.0, grey, "mono8", d32(cv::Rect(0, 0, 320, 240)).clone(), "32FC1");
  EXPECT_NE(e.error().find("depth image is 320x240 but the calibration says 640x480"),
            std::string::npos) << e.error();
  e = in->rgbd(4.1, grey, "mono8", d32, "16UC1");
  EXPECT_NE(e.error().find("encoding '16UC1' needs one 16-bit channel"), std::string::npos)
      << e.error();
  e = in->rgbd(4.2, grey, "mono8", d32, "64FC1");
  EXPECT_NE(e.error().find("unsupported encoding '64FC1' on the depth image"), std::string::npos);
  e = in->stereo(4.3, grey, grey, "mono8");
  EXPECT_NE(e.error().find("stereo images given to the RGB-D camera"), std::string::npos);
  EXPECT_EQ(in->errorCounts().size(), 4u);
}

TEST(CameraInput, DistortedColourIsUndistortedWithItsDepth) {
  const CameraCalibration calib = load("tum_fr1");
  auto in = CameraInput::create(calib);
  ASSERT_TRUE(in.ok()) << in.error();
  EXPECT_EQ(in->camera().K.fx, calib.rgbd.K.fx);
  const PinholeRadtan lens = calib.rgbd.colourCamera();
  cv::Mat colour(480, 640, CV_8UC3, cv::Scalar(0, 0, 0));
  cv::Mat depth(480, 640, CV_16UC1, cv::Scalar(15000));  // 3 m
  const std::vector<Vec2> dots = {{70.3, 60.7}, {590.8, 420.2}, {400.2, 300.6}};
  cv::Mat grey_in(480, 640, CV_8UC1, cv::Scalar(0));
  for (const Vec2& uv : dots) {
    drawSpot(&grey_in, uv);
    const cv::Rect patch(int(std::lround(uv.x())) - 3, int(std::lround(uv.y())) - 3, 7, 7);
    depth(patch).setTo(7500);  // 1.5 m where the dot is
  }
  cv::cvtColor(grey_in, colour, cv::COLOR_GRAY2RGB);
  auto f = in->rgbd(5.0, colour, "rgb8", depth, "16UC1");
  ASSERT_TRUE(f.ok()) << f.error();
  const auto spots = findSpots(f->left);
  ASSERT_EQ(spots.size(), dots.size());
  for (const Vec2& uv : dots) {
    const Vec2 expect = lens.undistortPixel(uv, calib.rgbd.K);
    const Vec2 got = nearest(spots, expect);
    EXPECT_LT((got - expect).norm(), 0.5) << uv.transpose() << " -> " << expect.transpose();
    const int ex = int(std::lround(expect.x())), ey = int(std::lround(expect.y()));
    EXPECT_FLOAT_EQ(f->depth.at<float>(ey, ex), 1.5f) << uv.transpose();
    if ((expect - uv).norm() > 5) {  // the patch left its distorted place
      const int ux = int(std::lround(uv.x())), uy = int(std::lround(uv.y()));
      EXPECT_FLOAT_EQ(f->depth.at<float>(uy, ux), 3.0f) << uv.transpose();
    }
  }
  EXPECT_GT((lens.undistortPixel(dots[0], calib.rgbd.K) - dots[0]).norm(), 5.0);
  // Nearest-neighbour depth: only values present in the input.
  for (int y = 0; y < 480; ++y)
    for (int x = 0; x < 640; ++x) {
      const float z = f->depth.at<float>(y, x);
      ASSERT_TRUE(z == 0.f || z == 1.5f || z == 3.0f) << x << "," << y << ": " << z;
    }
}

TEST(CameraInput, ParamsReadWriteValidate) {
  auto cfg = Config::fromString(
      "camera_input:\n  stereo_images: raw\n  depth_scale_16u: 1000\n  rgbd_slop: 0.015\n",
      "test.yaml");
  ASSERT_TRUE(cfg.ok()) << cfg.error();
  CameraInputParams p;
  ASSERT_TRUE(p.read(*cfg));
  EXPECT_EQ(p.stereo_images, "raw");
  EXPECT_EQ(p.depth_scale_16u, 1000.0);
  EXPECT_EQ(p.rgbd_slop, 0.015);
  EXPECT_TRUE(cfg->unusedKeys().empty());
  ConfigWriter w;
  p.write(&w);
  auto again = Config::fromString(w.yaml(), "written");
  ASSERT_TRUE(again.ok());
  CameraInputParams q;
  ASSERT_TRUE(q.read(*again));
  EXPECT_EQ(q.stereo_images, "raw");
  EXPECT_EQ(q.depth_scale_16u, 1000.0);
  EXPECT_EQ(q.sync_capacity, p.sync_capacity);

  auto bad = Config::fromString("camera_input:\n  sync_capacity: 0\n", "bad.yaml");
  ASSERT_TRUE(bad.ok());
  EXPECT_NE(p.read(*bad).error().find("sync_capacity"), std::string::npos);
  bad = Config::fromString("camera_input:\n  stereo_images: sideways\n", "bad.yaml");
  EXPECT_FALSE(p.read(*bad));
  p = CameraInputParams{};
  p.depth_scale_16u = -1;
  EXPECT_FALSE(p.validate());
  EXPECT_FALSE(CameraInput::create(load("tum_fr3"), p).ok());
}
