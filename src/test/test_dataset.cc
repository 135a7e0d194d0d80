#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include <opencv2/imgcodecs.hpp>

#include "hermes/core/dataset.h"

using namespace hermes;
namespace fs = std::filesystem;

namespace {

const std::string kMicro = std::string(HERMES_DATA_DIR) + "/euroc_V1_01_micro";

bool contains(const std::string& s, const std::string& part) {
  return s.find(part) != std::string::npos;
}

}  // namespace

TEST(Dataset, ProbesRealEurocWithRectifiedCamera) {
  auto info = probeDataset(kMicro);
  ASSERT_TRUE(info.ok()) << info.error();
  EXPECT_EQ(info->kind, DatasetKind::kEuroc);
  EXPECT_EQ(info->frame_count, 40u);
  ASSERT_TRUE(info->stereo.has_value());
  EXPECT_FALSE(info->rgbd.has_value());
  EXPECT_EQ(info->groundtruth.size(), 42u);
  EXPECT_NEAR(info->baseline, 0.110, 0.002);
  EXPECT_NEAR(info->t_end - info->t_start, 1.95, 1e-6);
  EXPECT_TRUE(info->warnings.empty());
  // The tracked camera is the rectified left one: close to, but not equal to, cam0.
  const double angle = angularDistance(info->T_B_C, info->stereo->left.T_B_C);
  EXPECT_GT(angle, 1e-4);
  EXPECT_LT(angle, 0.05);
  EXPECT_LT(translationalDistance(info->T_B_C, info->stereo->left.T_B_C), 1e-12);
  std::printf("[ dataset ] %s\n", info->summary().c_str());
}

TEST(Dataset, LoadsRectifiedOrRawStereo) {
  auto ds = Dataset::open(kMicro);
  ASSERT_TRUE(ds.ok()) << ds.error();
  ASSERT_NE((*ds)->rectification(), nullptr);
  auto f = (*ds)->loadStereo(39);
  ASSERT_TRUE(f.ok()) << f.error();
  EXPECT_TRUE(f->rectified);
  EXPECT_EQ(f->left.size(), cv::Size(752, 480));
  EXPECT_EQ(f->stamp_ns, 1403715275212143104LL);
  EXPECT_DOUBLE_EQ((*ds)->frameTime(39), f->t);
  EXPECT_FALSE((*ds)->loadRgbd(0).ok());

  DatasetParams p;
  p.rectify = false;
  auto raw = Dataset::open(kMicro + "/mav0", p);
  ASSERT_TRUE(raw.ok()) << raw.error();
  EXPECT_EQ((*raw)->rectification(), nullptr);
  auto fr = (*raw)->loadStereo(39);
  ASSERT_TRUE(fr.ok()) << fr.error();
  EXPECT_FALSE(fr->rectified);
  EXPECT_GT(cv::norm(fr->left, f->left, cv::NORM_L1), 0.0);  // rectification changed pixels
  EXPECT_LT(translationalDistance((*raw)->info().T_B_C, (*raw)->info().stereo->left.T_B_C), 1e-15);
}

TEST(Dataset, ProbesTumFolder) {
  const fs::path dir = fs::path(::testing::TempDir()) / "door_tum";
  fs::remove_all(dir);
  fs::create_directories(dir);
  std::ofstream rgb(dir / "rgb.txt"), depth(dir / "depth.txt");
  for (int i = 0; i < 3; ++i) {
    const std::string n = std::to_string(i) + ".png";
    cv::imwrite((dir / ("c" + n)).string(), cv::Mat(480, 640, CV_8UC3, cv::Scalar(i, i, i)));
    cv::imwrite((dir / ("d" + n)).string(), cv::Mat(480, 640, CV_16UC1, cv::Scalar(5000 * (i + 1))));
    rgb << 5.0 + 0.1 * i << " c" << n << "\n";
    depth << 5.01 + 0.1 * i << " d" << n << "\n";
  }
  rgb.close();
  depth.close();
  auto ds = Dataset::open(dir.string());
  ASSERT_TRUE(ds.ok()) << ds.error();
  const DatasetInfo& info = (*ds)->info();
  EXPECT_EQ(info.kind, DatasetKind::kTum);
  EXPECT_EQ(info.frame_count, 3u);
  EXPECT_TRUE(info.rgbd.has_value());
  EXPECT_TRUE(info.groundtruth.empty());
  EXPECT_DOUBLE_EQ(info.K.fx, 481.20);
  ASSERT_FALSE(info.warnings.empty());
  EXPECT_TRUE(contains(info.warnings[0], "ICL-NUIM"));
  auto f = (*ds)->loadRgbd(2);
  ASSERT_TRUE(f.ok()) << f.error();
  EXPECT_FLOAT_EQ(f->depth_m.at<float>(100, 100), 3.0f);
  EXPECT_FALSE((*ds)->loadStereo(0).ok());

  DatasetParams p;
  p.tum_max_dt = 0.005;  // the 10 ms offset is now too far
  EXPECT_FALSE(Dataset::open(dir.string(), p).ok());
}

TEST(Dataset, UnknownLayoutAndParamsAreErrors) {
  const fs::path empty = fs::path(::testing::TempDir()) / "door_empty";
  fs::create_directories(empty);
  auto r = probeDataset(empty.string());
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.error(), empty.string())) << r.error();
  EXPECT_FALSE(probeDataset("/no/such/dir").ok());

  auto cfg = Config::fromString("dataset:\n  tum_max_dt: 0.05\n  rectify: false\n", "test");
  ASSERT_TRUE(cfg.ok()) << cfg.error();
  DatasetParams p;
  ASSERT_TRUE(p.read(*cfg));
  EXPECT_DOUBLE_EQ(p.tum_max_dt, 0.05);
  EXPECT_FALSE(p.rectify);
  ConfigWriter w;
  p.write(w);
  EXPECT_TRUE(contains(w.yaml(), "tum_max_dt"));
  auto bad = Config::fromString("dataset:\n  tum_max_dt: -1\n", "test");
  ASSERT_TRUE(bad.ok());
  DatasetParams q;
  Status s = q.read(*bad);
  ASSERT_FALSE(s.ok());
  EXPECT_TRUE(contains(s.error(), "dataset.tum_max_dt")) << s.error();
}
