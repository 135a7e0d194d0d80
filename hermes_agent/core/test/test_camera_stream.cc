#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "hermes/agent/camera_stream.h"
#include "hermes/agent/dataset_feed.h"

using namespace hermes;
using namespace hermes::agent;

namespace {

const std::string kCameras = std::string(HERMES_SOURCE_DIR) + "/config/cameras";

CameraCalibration load(const std::string& name) {
  auto c = loadCameraCalibration(name, kCameras);
  HERMES_CHECK(c.ok(), c.error());
  return *c;
}

InputImage image(double stamp, const std::string& encoding, int type, int w, int h,
                 double value = 100) {
  InputImage im;
  im.stamp = stamp;
  im.encoding = encoding;
  im.image = cv::Mat(h, w, type, cv::Scalar::all(value));
  return im;
}

bool contains(const std::string& s, const std::string& part) {
  return s.find(part) != std::string::npos;
}

}  // namespace

TEST(CameraStream, UnsynchronisedRgbdPairsInOrder) {
  // TUM-like: 30 Hz colour, depth stamped up to 12 ms away, some depth missing.
  auto s = CameraStream::create(load("tum_fr3"), {}, "/camera/rgb/image_color",
                                "/camera/depth/image");
  ASSERT_TRUE(s.ok()) << s.error();
  std::vector<double> out;
  for (int k = 0; k < 60; ++k) {
    const double t = 100.0 + k / 30.0;
    const double dt = 0.001 * ((k * 7) % 25 - 12);  // [-12, 12] ms
    s->pushA(image(t, "rgb8", CV_8UC3, 640, 480));
    if (k % 10 != 5) s->pushB(image(t + dt, "32FC1", CV_32FC1, 640, 480, 2.0));
    while (auto f = s->next()) {
      EXPECT_EQ(f->left.type(), CV_8UC1);
      EXPECT_EQ(f->depth.type(), CV_32FC1);
      EXPECT_FLOAT_EQ(f->depth.at<float>(240, 320), 2.0f);
      out.push_back(f->stamp);
    }
  }
  // Every colour image with a depth partner became a frame, in order; the
  // last one may still wait for a later depth image.
  EXPECT_GE(out.size(), 53u);
  for (std::size_t i = 1; i < out.size(); ++i) EXPECT_GT(out[i], out[i - 1]);
  const StreamCounters c = s->counters();
  EXPECT_EQ(c.received_a, 60);
  EXPECT_EQ(c.received_b, 54);
  EXPECT_EQ(c.converted, static_cast<std::int64_t>(out.size()));
  EXPECT_GE(c.unpaired_a, 5);  // the colour images whose depth never came
  EXPECT_EQ(c.rejected, 0);
  EXPECT_TRUE(s->problems().empty());
}

TEST(CameraStream, RejectedPairsAreCountedAndReportedOncePerCause) {
  auto s = CameraStream::create(load("euroc"), {}, "/cam0/image_raw", "/cam1/image_raw");
  ASSERT_TRUE(s.ok()) << s.error();
  EXPECT_TRUE(s->isStereo());
  for (int k = 0; k < 5; ++k) {
    const double t = 10 + 0.05 * k;
    s->pushA(image(t, "yuv422", CV_8UC2, 752, 480));
    s->pushB(image(t, "yuv422", CV_8UC2, 752, 480));
    EXPECT_FALSE(s->next().has_value());
  }
  for (int k = 5; k < 8; ++k) {  // right in another encoding
    const double t = 10 + 0.05 * k;
    s->pushA(image(t, "mono8", CV_8UC1, 752, 480));
    s->pushB(image(t, "bgr8", CV_8UC3, 752, 480));
    EXPECT_FALSE(s->next().has_value());
  }
  s->pushA(image(11, "mono8", CV_8UC1, 640, 480));  // wrong size
  s->pushB(image(11, "mono8", CV_8UC1, 640, 480));
  EXPECT_FALSE(s->next().has_value());
  s->pushA(image(12, "mono8", CV_8UC1, 752, 480));  // good
  s->pushB(image(12, "mono8", CV_8UC1, 752, 480));
  auto f = s->next();
  ASSERT_TRUE(f.has_value());
  EXPECT_EQ(f->stamp, 12);
  EXPECT_EQ(f->left.cols, s->camera().K.width);

  const std::vector<std::string> p = s->problems();
  ASSERT_EQ(p.size(), 3u);  // one line per cause
  EXPECT_TRUE(contains(p[0], "unsupported encoding") && contains(p[0], "yuv422")) << p[0];
  EXPECT_TRUE(contains(p[1], "encodings differ") && contains(p[1], "/cam1/image_raw")) << p[1];
  EXPECT_TRUE(contains(p[2], "size mismatch") && contains(p[2], "640x480")) << p[2];
  EXPECT_TRUE(s->problems().empty());  // reported once
  const StreamCounters c = s->counters();
  EXPECT_EQ(c.rejected, 9);
  EXPECT_EQ(c.rejected_by_cause.at("unsupported encoding"), 5);
  EXPECT_EQ(c.rejected_by_cause.at("encodings differ"), 3);
  EXPECT_EQ(c.rejected_by_cause.at("size mismatch"), 1);
  EXPECT_EQ(c.converted, 1);
}

TEST(CameraStream, StereoStampsThatNeverPairAreReportedOnce) {
  // The right camera's clock is 40 ms off: nothing pairs within 1 ms.
  auto s = CameraStream::create(load("euroc"), {}, "/cam0/image_raw", "/cam1/image_raw");
  ASSERT_TRUE(s.ok()) << s.error();
  std::vector<std::string> problems;
  for (int k = 0; k < 40; ++k) {
    const double t = 5 + 0.05 * k;
    s->pushA(image(t, "mono8", CV_8UC1, 752, 480));
    s->pushB(image(t + 0.04, "mono8", CV_8UC1, 752, 480));
    EXPECT_FALSE(s->next().has_value());
    for (const std::string& p : s->problems()) problems.push_back(p);
  }
  ASSERT_EQ(problems.size(), 1u);
  EXPECT_TRUE(contains(problems[0], "never pair")) << problems[0];
  EXPECT_TRUE(contains(problems[0], "/cam0/image_raw") && contains(problems[0], "/cam1/image_raw"))
      << problems[0];
  EXPECT_TRUE(contains(problems[0], "stereo_slop")) << problems[0];
  EXPECT_EQ(s->counters().paired, 0);

  // The same stamps with a slop that covers the offset pair.
  CameraInputParams wide;
  wide.stereo_slop = 0.045;
  auto w = CameraStream::create(load("euroc"), wide, "l", "r");
  ASSERT_TRUE(w.ok()) << w.error();
  int frames = 0;
  for (int k = 0; k < 40; ++k) {
    const double t = 5 + 0.05 * k;
    w->pushA(image(t, "mono8", CV_8UC1, 752, 480));
    w->pushB(image(t + 0.04, "mono8", CV_8UC1, 752, 480));
    while (w->next()) ++frames;
  }
  EXPECT_EQ(frames, 40);
  EXPECT_TRUE(w->problems().empty());
}

TEST(CameraStream, FramesOwnTheirPixels) {
  // Rectified mono8 stereo passes through CameraInput unchanged: the frame must
  // not keep pointing into the input buffers, which go away with their owners
  // (a ROS message is freed once its pair is handed out).
  CameraInputParams rectified;
  rectified.stereo_images = "rectified";
  CameraCalibration c = load("euroc");
  auto rect = rectify(c.stereo);
  ASSERT_TRUE(rect.ok()) << rect.error();
  c.stereo.left.K = c.stereo.right.K = rect->K;
  c.stereo.left.dist.fill(0);
  c.stereo.right.dist.fill(0);
  c.stereo.left.T_B_C = rect->T_B_Crect;
  c.stereo.right.T_B_C = rect->T_B_Crect * SE3(Mat3::Identity(), Vec3(rect->baseline, 0, 0));
  c.rectified = true;
  c.width = rect->K.width;
  c.height = rect->K.height;
  auto s = CameraStream::create(c, rectified, "l", "r");
  ASSERT_TRUE(s.ok()) << s.error();
  auto buffer = std::make_shared<std::vector<std::uint8_t>>(std::size_t(c.width) * c.height, 77);
  std::weak_ptr<std::vector<std::uint8_t>> alive = buffer;
  for (bool left : {true, false}) {
    InputImage im;
    im.stamp = 3.0;
    im.encoding = "mono8";
    im.image = cv::Mat(c.height, c.width, CV_8UC1, buffer->data());
    im.owner = buffer;
    if (left) s->pushA(std::move(im));
    else s->pushB(std::move(im));
  }
  buffer.reset();  // only the stream holds the buffer now
  auto f = s->next();
  ASSERT_TRUE(f.has_value());
  EXPECT_TRUE(alive.expired()) << "the pair's buffers are released once the frame is out";
  EXPECT_NE(f->left.u, nullptr) << "the frame must own (reference-count) its pixels";
  EXPECT_NE(f->right.u, nullptr);
  EXPECT_EQ(f->left.at<std::uint8_t>(10, 10), 77);
  EXPECT_EQ(f->right.at<std::uint8_t>(c.height - 1, c.width - 1), 77);
}

TEST(CameraStream, DatasetCalibrationDescribesTheLoadedFrames) {
  // The real EuRoC micro clip, rectified by the dataset (what the DatasetPlayer
  // publishes) and raw: CameraInput must hand the pipeline the same camera and
  // the same pixels as the dataset's own rectification.
  const std::string micro = std::string(HERMES_DATA_DIR) + "/euroc_V1_01_micro";
  auto rect = Dataset::open(micro);
  ASSERT_TRUE(rect.ok()) << rect.error();
  const DatasetInfo& info = (*rect)->info();
  const CameraCalibration c = datasetCalibration(**rect);
  EXPECT_TRUE(c.rectified);
  EXPECT_EQ(c.source, info.root);
  auto in = CameraInput::create(c);
  ASSERT_TRUE(in.ok()) << in.error();
  EXPECT_DOUBLE_EQ(in->camera().K.fx, info.K.fx);
  EXPECT_DOUBLE_EQ(in->camera().K.cx, info.K.cx);
  EXPECT_NEAR(in->camera().baseline, info.baseline, 1e-12);
  EXPECT_LT((in->camera().T_B_C.inverse() * info.T_B_C).log().norm(), 1e-12);
  auto f = loadCameraFrame(**rect, 3);
  ASSERT_TRUE(f.ok()) << f.error();
  auto passed = in->stereo(f->stamp, f->left, f->right, "mono8");
  ASSERT_TRUE(passed.ok()) << passed.error();
  EXPECT_EQ(cv::norm(passed->left, f->left, cv::NORM_INF), 0);

  DatasetParams raw_params;
  raw_params.rectify = false;
  auto raw = Dataset::open(micro, raw_params);
  ASSERT_TRUE(raw.ok()) << raw.error();
  const CameraCalibration rc = datasetCalibration(**raw);
  EXPECT_FALSE(rc.rectified);
  EXPECT_TRUE(rc.stereo.left.hasDistortion());
  auto rin = CameraInput::create(rc);
  ASSERT_TRUE(rin.ok()) << rin.error();
  EXPECT_NEAR(rin->camera().K.fx, info.K.fx, 1e-9);
  EXPECT_NEAR(rin->camera().baseline, info.baseline, 1e-12);
  auto fr = loadCameraFrame(**raw, 3);
  ASSERT_TRUE(fr.ok()) << fr.error();
  auto rectified = rin->stereo(fr->stamp, fr->left, fr->right, "mono8");
  ASSERT_TRUE(rectified.ok()) << rectified.error();
  EXPECT_EQ(cv::norm(rectified->left, f->left, cv::NORM_INF), 0);  // same maps, same pixels
}
