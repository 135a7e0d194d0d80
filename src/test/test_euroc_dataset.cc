#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

#include "hermes/core/euroc_dataset.h"

using namespace hermes;
namespace fs = std::filesystem;

namespace {

const std::string kMicro = std::string(HERMES_DATA_DIR) + "/euroc_V1_01_micro";

bool contains(const std::string& s, const std::string& part) {
  return s.find(part) != std::string::npos;
}

// Copies the micro dataset's text files (not the images: a symlink to each
// data/ folder keeps it fast) into a fresh temp folder that a test may break.
std::string brokenCopy(const std::string& name) {
  const fs::path dst = fs::path(::testing::TempDir()) / ("euroc_" + name);
  fs::remove_all(dst);
  const fs::path src = fs::path(kMicro) / "mav0";
  for (const char* cam : {"cam0", "cam1"}) {
    fs::create_directories(dst / "mav0" / cam);
    fs::copy_file(src / cam / "data.csv", dst / "mav0" / cam / "data.csv");
    fs::copy_file(src / cam / "sensor.yaml", dst / "mav0" / cam / "sensor.yaml");
    fs::create_directory_symlink(src / cam / "data", dst / "mav0" / cam / "data");
  }
  fs::create_directories(dst / "mav0" / "state_groundtruth_estimate0");
  fs::copy_file(src / "state_groundtruth_estimate0" / "data.csv",
                dst / "mav0" / "state_groundtruth_estimate0" / "data.csv");
  return dst.string();
}

void replaceLine(const std::string& path, int lineno, const std::string& text) {
  std::ifstream in(path);
  std::ostringstream out;
  std::string line;
  for (int n = 1; std::getline(in, line); ++n) out << (n == lineno ? text : line) << "\n";
  in.close();
  std::ofstream(path) << out.str();
}

}  // namespace

TEST(EurocCameraYaml, ReadsRealCalibrationExactly) {
  auto c = readEurocCameraYaml(kMicro + "/mav0/cam0/sensor.yaml");
  ASSERT_TRUE(c.ok()) << c.error();
  EXPECT_EQ(c->K.width, 752);
  EXPECT_EQ(c->K.height, 480);
  EXPECT_DOUBLE_EQ(c->K.fx, 458.654);
  EXPECT_DOUBLE_EQ(c->K.fy, 457.296);
  EXPECT_DOUBLE_EQ(c->K.cx, 367.215);
  EXPECT_DOUBLE_EQ(c->K.cy, 248.375);
  EXPECT_DOUBLE_EQ(c->dist[0], -0.28340811);
  EXPECT_DOUBLE_EQ(c->dist[1], 0.07395907);
  EXPECT_DOUBLE_EQ(c->dist[2], 0.00019359);
  EXPECT_DOUBLE_EQ(c->dist[3], 1.76187114e-05);
  EXPECT_DOUBLE_EQ(c->rate_hz, 20.0);
  const Mat4 T = c->T_B_C.matrix();
  // Values straight from the file; SE3 re-normalises the rotation, so allow 1e-9.
  EXPECT_NEAR(T(0, 0), 0.0148655429818, 1e-9);
  EXPECT_NEAR(T(0, 1), -0.999880929698, 1e-9);
  EXPECT_NEAR(T(1, 3), -0.064676986768, 1e-12);
  EXPECT_NEAR(T(2, 3), 0.00981073058949, 1e-12);
  const Mat3 R = T.topLeftCorner<3, 3>();
  EXPECT_LT((R.transpose() * R - Mat3::Identity()).norm(), 1e-12);
  EXPECT_NEAR(R.determinant(), 1.0, 1e-12);
}

TEST(EurocCameraYaml, WriterRoundTrips) {
  auto c = readEurocCameraYaml(kMicro + "/mav0/cam1/sensor.yaml");
  ASSERT_TRUE(c.ok()) << c.error();
  const std::string path = ::testing::TempDir() + "/written_sensor.yaml";
  ASSERT_TRUE(writeEurocCameraYaml(path, *c, "round trip"));
  auto back = readEurocCameraYaml(path);
  ASSERT_TRUE(back.ok()) << back.error();
  EXPECT_DOUBLE_EQ(back->K.fx, c->K.fx);
  EXPECT_DOUBLE_EQ(back->K.cy, c->K.cy);
  EXPECT_EQ(back->K.width, c->K.width);
  for (int i = 0; i < 4; ++i) EXPECT_DOUBLE_EQ(back->dist[i], c->dist[i]);
  EXPECT_LT((back->T_B_C.matrix() - c->T_B_C.matrix()).norm(), 1e-14);
  std::ifstream in(path);
  std::string first;
  std::getline(in, first);
  EXPECT_EQ(first, "%YAML:1.0");  // same dialect as EuRoC's own files
}

TEST(EurocCameraYaml, RejectsUnsupportedModelsNamingTheFile) {
  const std::string path = ::testing::TempDir() + "/fisheye_sensor.yaml";
  std::ifstream in(kMicro + "/mav0/cam0/sensor.yaml");
  std::stringstream ss;
  ss << in.rdbuf();
  std::string text = ss.str();
  text.replace(text.find("radial-tangential"), 17, "equidistant");
  std::ofstream(path) << text;
  auto c = readEurocCameraYaml(path);
  ASSERT_FALSE(c.ok());
  EXPECT_TRUE(contains(c.error(), path)) << c.error();
  EXPECT_TRUE(contains(c.error(), "equidistant")) << c.error();

  text.replace(text.find("pinhole"), 7, "omni");
  std::ofstream(path) << text;
  c = readEurocCameraYaml(path);
  ASSERT_FALSE(c.ok());
  EXPECT_TRUE(contains(c.error(), "omni")) << c.error();
  EXPECT_FALSE(readEurocCameraYaml("/no/such/sensor.yaml").ok());
}

TEST(EurocDataset, LoadsRealMicroSequence) {
  const auto t0 = std::chrono::steady_clock::now();
  auto ds = EurocDataset::open(kMicro);
  const double open_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_TRUE(ds.ok()) << ds.error();
  EXPECT_EQ(ds->size(), 40u);
  EXPECT_EQ(ds->skipped().cam1_missing_image, 0);
  EXPECT_EQ(ds->skipped().cam0_missing_image, 0);
  EXPECT_EQ(ds->skipped().cam0_unpaired, 0);
  EXPECT_EQ(ds->skipped().cam1_unpaired, 0);
  EXPECT_EQ(ds->pairs().front().stamp_ns, 1403715273262142976LL);
  EXPECT_EQ(ds->pairs().back().stamp_ns, 1403715275212143104LL);
  EXPECT_DOUBLE_EQ(ds->cam1().K.fx, 457.587);

  ASSERT_TRUE(ds->hasGroundTruth());
  EXPECT_EQ(ds->groundTruth().size(), 42u);
  EXPECT_EQ(ds->groundTruthStampsNs().front(), 1403715273262142976LL);
  const auto& g0 = ds->groundTruth().front();
  EXPECT_NEAR(g0.T_W_B.translation().x(), 0.878895, 1e-12);
  EXPECT_NEAR(g0.T_W_B.quat().w(), 0.069433 / Quat(0.069433, -0.824237, -0.106942, -0.551702).norm(),
              1e-12);
  // Seconds keep sub-microsecond precision: 1403715273.262142976 s.
  EXPECT_NEAR(g0.t - 1403715273.0, 0.262142976, 1e-6);

  // The same folder given as .../mav0 works too.
  auto ds2 = EurocDataset::open(kMicro + "/mav0");
  ASSERT_TRUE(ds2.ok()) << ds2.error();
  EXPECT_EQ(ds2->size(), 40u);

  const auto t1 = std::chrono::steady_clock::now();
  auto f = ds->load(10);
  const double load_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t1).count();
  ASSERT_TRUE(f.ok()) << f.error();
  EXPECT_EQ(f->stamp_ns, ds->pairs()[10].stamp_ns);
  EXPECT_EQ(f->left.type(), CV_8UC1);
  EXPECT_EQ(f->left.cols, 752);
  EXPECT_EQ(f->right.rows, 480);
  EXPECT_NEAR(f->t - nsToSeconds(f->stamp_ns), 0.0, 1e-12);
  EXPECT_FALSE(ds->load(40).ok());
  std::printf("[ euroc   ] open %.1f ms, load one pair %.1f ms\n", open_ms, load_ms);
}

TEST(EurocDataset, NsToSecondsKeepsPrecision) {
  const std::int64_t ns = 1403715273262142976LL;
  const double t = nsToSeconds(ns);
  // Double spacing at 1.4e9 s is 2.4e-7 s; the conversion must be within half of it.
  EXPECT_LE(std::abs((t - 1403715273.0) - 0.262142976), 1.2e-7);
  EXPECT_EQ(nsToSeconds(1500000000LL), 1.5);
}

TEST(EurocDataset, MissingFolderAndFilesAreNamed) {
  auto r = EurocDataset::open("/no/such/euroc");
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.error(), "/no/such/euroc")) << r.error();

  const std::string dir = brokenCopy("nocsv");
  fs::remove(fs::path(dir) / "mav0/cam1/data.csv");
  r = EurocDataset::open(dir);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.error(), dir + "/mav0/cam1/data.csv")) << r.error();

  const std::string dir2 = brokenCopy("noyaml");
  fs::remove(fs::path(dir2) / "mav0/cam0/sensor.yaml");
  r = EurocDataset::open(dir2);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.error(), dir2 + "/mav0/cam0/sensor.yaml")) << r.error();
}

TEST(EurocDataset, CorruptedLinesAreNamedWithLineNumber) {
  std::string dir = brokenCopy("badcsv");
  std::string csv = dir + "/mav0/cam0/data.csv";
  replaceLine(csv, 7, "14037152733x2143104,1403715273312143104.png");
  auto r = EurocDataset::open(dir);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.error(), csv + ":7")) << r.error();

  dir = brokenCopy("badgt");
  csv = dir + "/mav0/state_groundtruth_estimate0/data.csv";
  replaceLine(csv, 12, "1403715273812142848,0.8789,2.18,nan-ish");
  r = EurocDataset::open(dir);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.error(), csv + ":12")) << r.error();

  dir = brokenCopy("unsorted");
  csv = dir + "/mav0/cam1/data.csv";
  replaceLine(csv, 3, "1403715273162142976,1403715273162142976.png");
  r = EurocDataset::open(dir);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.error(), csv + ":3")) << r.error();
}

TEST(EurocDataset, MissingImageIsSkippedAndUnreadableImageNamed) {
  const std::string dir = brokenCopy("missingimg");
  // Replace cam0's data symlink by a folder with all but two images and one broken file.
  const fs::path data = fs::path(dir) / "mav0/cam0/data";
  fs::remove(data);
  fs::create_directory(data);
  const fs::path src = fs::path(kMicro) / "mav0/cam0/data";
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(src)) files.push_back(e.path());
  std::sort(files.begin(), files.end());
  for (std::size_t i = 0; i < files.size(); ++i) {
    if (i == 3 || i == 30) continue;
    fs::create_symlink(files[i], data / files[i].filename());
  }
  fs::remove(data / files[0].filename());
  std::ofstream(data / files[0].filename()) << "not a png";
  auto r = EurocDataset::open(dir);
  ASSERT_TRUE(r.ok()) << r.error();
  EXPECT_EQ(r->size(), 38u);
  EXPECT_EQ(r->skipped().cam0_missing_image, 2);
  EXPECT_EQ(r->skipped().cam1_unpaired, 2);
  auto f = r->load(0);
  ASSERT_FALSE(f.ok());
  EXPECT_TRUE(contains(f.error(), (data / files[0].filename()).string())) << f.error();
  EXPECT_TRUE(r->load(1).ok());
}

TEST(EurocCameraYaml, MutatedFilesNeverCrash) {
  std::ifstream in(kMicro + "/mav0/cam0/sensor.yaml");
  std::stringstream ss;
  ss << in.rdbuf();
  const std::string original = ss.str();
  const std::string path = ::testing::TempDir() + "/mutated_sensor.yaml";
  std::mt19937 rng(3);
  int errors = 0;
  for (int trial = 0; trial < 200; ++trial) {
    std::string text = original;
    const int flips = 1 + trial % 4;
    for (int k = 0; k < flips; ++k) {
      const std::size_t pos = rng() % text.size();
      const char pool[] = "[]{}:,-#. \n0123456789eaz\"'";
      text[pos] = pool[rng() % (sizeof(pool) - 1)];
    }
    if (trial % 7 == 0) text.resize(rng() % text.size());  // truncated file
    std::ofstream(path, std::ios::trunc) << text;
    auto c = readEurocCameraYaml(path);
    if (!c.ok()) {
      ++errors;
      EXPECT_TRUE(contains(c.error(), path)) << c.error();
      continue;
    }
    // Whatever parses must still be a usable camera.
    EXPECT_GT(c->K.fx, 0);
    EXPECT_GT(c->K.width, 0);
    EXPECT_TRUE(c->T_B_C.matrix().allFinite());
  }
  EXPECT_GT(errors, 20);
}
