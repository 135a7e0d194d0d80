// Dataset folders as KITTI odometry and ICL-NUIM publish them, on the real clips
// shipped in data/ (data/README.md), and their readers' errors.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "hermes/core/dataset.h"
#include "hermes/core/eval_io.h"
#include "hermes/core/kitti_dataset.h"
#include "hermes/core/tum_dataset.h"

using namespace hermes;
namespace fs = std::filesystem;

namespace {

const std::string kKitti = std::string(HERMES_DATA_DIR) + "/kitti_odometry_06";
const std::string kKittiSeq = kKitti + "/sequences/06";
const std::string kIcl = std::string(HERMES_DATA_DIR) + "/iclnuim_office_kt0/traj0_frei_png";

bool contains(const std::string& s, const std::string& part) {
  return s.find(part) != std::string::npos;
}

fs::path freshDir(const std::string& name) {
  const fs::path d = fs::path(::testing::TempDir()) / ("layouts_" + name);
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

/// A KITTI copy: sequences/06 with symlinked images, the given files written anew.
fs::path kittiCopy(const std::string& name, bool with_times, const std::string& calib) {
  const fs::path root = freshDir(name);
  const fs::path seq = root / "sequences" / "06";
  fs::create_directories(seq);
  for (const char* cam : {"image_0", "image_1"}) fs::create_directory_symlink(fs::path(kKittiSeq) / cam, seq / cam);
  std::ofstream(seq / "calib.txt") << calib;
  if (with_times) fs::copy_file(fs::path(kKittiSeq) / "times.txt", seq / "times.txt");
  return seq;
}

std::string readAll(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

}  // namespace

TEST(KittiLayout, ReadsTheSequenceAsPublished) {
  auto ds = Dataset::open(kKittiSeq);
  ASSERT_TRUE(ds.ok()) << ds.error();
  const DatasetInfo& info = (*ds)->info();
  EXPECT_EQ(info.kind, DatasetKind::kKitti);
  EXPECT_EQ(info.layout, "kitti");
  EXPECT_TRUE(isStereo(info.kind));
  EXPECT_EQ(info.frame_count, 30u);
  EXPECT_DOUBLE_EQ(info.K.fx, 707.0912);
  EXPECT_DOUBLE_EQ(info.K.cy, 183.1104);
  EXPECT_EQ(info.K.width, 1226);
  EXPECT_EQ(info.K.height, 370);
  EXPECT_NEAR(info.baseline, 379.8145 / 707.0912, 1e-12);  // -P1[0,3] / fx
  EXPECT_TRUE(info.warnings.empty());
  // Stamps from times.txt; ground truth from ../../poses/06.txt, one pose per frame,
  // the left camera's (T_B_C identity).
  EXPECT_DOUBLE_EQ((*ds)->frameTime(1), 1.044989e-01);
  ASSERT_EQ(info.groundtruth.size(), 30u);
  EXPECT_DOUBLE_EQ(info.groundtruth[1].t, 1.044989e-01);
  EXPECT_NEAR(info.groundtruth[1].T_W_B.translation().z(), 1.198998, 1e-9);
  EXPECT_LT(info.groundtruth[0].T_W_B.translation().norm(), 1e-9);
  EXPECT_LT(info.T_B_C.translation().norm() + info.T_B_C.quat().vec().norm(), 1e-15);
  EXPECT_GT(info.groundtruth.back().T_W_B.translation().z(), 30.0);  // ~1.2 m a frame
  ASSERT_TRUE((*ds)->stereoRectified());
  auto f = (*ds)->loadStereo(29);
  ASSERT_TRUE(f.ok()) << f.error();
  EXPECT_TRUE(f->rectified);
  EXPECT_EQ(f->left.size(), cv::Size(1226, 370));
  EXPECT_EQ(f->right.type(), CV_8UC1);
  EXPECT_FALSE((*ds)->loadRgbd(0).ok());
  EXPECT_FALSE((*ds)->loadStereo(30).ok());
}

TEST(KittiLayout, WithoutTimesTheNominalRateIsUsedAndSaid) {
  const fs::path seq = kittiCopy("notimes", false, readAll(kKittiSeq + "/calib.txt"));
  auto ds = Dataset::open(seq.string());
  ASSERT_TRUE(ds.ok()) << ds.error();
  ASSERT_EQ((*ds)->info().warnings.size(), 1u);
  EXPECT_TRUE(contains((*ds)->info().warnings[0], "10 Hz")) << (*ds)->info().warnings[0];
  EXPECT_DOUBLE_EQ((*ds)->frameTime(3), 0.3);
  EXPECT_TRUE((*ds)->info().groundtruth.empty());  // no poses/06.txt beside this copy
}

TEST(KittiLayout, BadCalibrationAndRootFolderAreNamed) {
  const std::string calib = readAll(kKittiSeq + "/calib.txt");
  const std::string no_p1 = calib.substr(0, calib.find("P1:"));
  auto a = Dataset::open(kittiCopy("nop1", true, no_p1).string());
  ASSERT_FALSE(a.ok());
  EXPECT_TRUE(contains(a.error(), "calib.txt")) << a.error();
  EXPECT_TRUE(contains(a.error(), "P1:")) << a.error();
  auto b = Dataset::open(kittiCopy("short", true, "P0: 1 2 3\nP1: 1 0 0 -1 0 1 0 0 0 0 1 0\n").string());
  ASSERT_FALSE(b.ok());
  EXPECT_TRUE(contains(b.error(), "calib.txt:1")) << b.error();
  // The KITTI root instead of one of its sequences: the error says which to give.
  auto c = detectDatasetKind(kKitti);
  ASSERT_FALSE(c.ok());
  EXPECT_TRUE(contains(c.error(), "sequences/00")) << c.error();
  EXPECT_TRUE(contains(c.error(), "ICL-NUIM (associations.txt)")) << c.error();
  // A poses file has no stamps: eval asks for the sequence folder instead.
  auto d = eval::readTrajectoryForEval(kKitti + "/poses/06.txt");
  ASSERT_FALSE(d.ok());
  EXPECT_TRUE(contains(d.error(), "sequences/NN")) << d.error();
  auto e = eval::readTrajectoryForEval(kKittiSeq);
  ASSERT_TRUE(e.ok()) << e.error();
  EXPECT_EQ(e->size(), 30u);
}

TEST(IclNuimLayout, ReadsTheReleaseAsPublished) {
  auto ds = Dataset::open(kIcl);
  ASSERT_TRUE(ds.ok()) << ds.error();
  const DatasetInfo& info = (*ds)->info();
  EXPECT_EQ(info.kind, DatasetKind::kTum);
  EXPECT_EQ(info.layout, "icl_nuim");
  EXPECT_EQ(info.frame_count, 40u);
  EXPECT_DOUBLE_EQ(info.K.fy, 480.0);  // the images as stored
  // Frame-index stamps at 30 Hz: image K.png at K / 30 s.
  EXPECT_DOUBLE_EQ((*ds)->frameTime(0), 1.0 / 30.0);
  EXPECT_DOUBLE_EQ((*ds)->frameTime(39), 40.0 / 30.0);
  // The whole published ground truth (index 2..1508), on the same time base.
  ASSERT_EQ(info.groundtruth.size(), 1507u);
  EXPECT_DOUBLE_EQ(info.groundtruth.front().t, 2.0 / 30.0);
  auto f = (*ds)->loadRgbd(5);
  ASSERT_TRUE(f.ok()) << f.error();
  EXPECT_EQ(f->depth_m.type(), CV_32FC1);
  EXPECT_DOUBLE_EQ(f->t, 6.0 / 30.0);
  bool said = false;
  for (const auto& w : info.warnings) said = said || contains(w, "mirrored");
  EXPECT_TRUE(said);
}

TEST(IclNuimLayout, GroundTruthIsMirroredConsistently) {
  const std::string file = kIcl + "/traj0.gt.freiburg";
  auto raw = readTumTrajectory(file);
  ASSERT_TRUE(raw.ok()) << raw.error();
  auto gt = readIclNuimGroundTruth(file);
  ASSERT_TRUE(gt.ok()) << gt.error();
  ASSERT_EQ(gt->size(), raw->size());
  const Mat3 M = Vec3(1, -1, 1).asDiagonal();
  for (std::size_t i = 0; i < gt->size(); i += 100) {
    const SE3& a = (*raw)[i].T_W_B;
    const SE3& b = (*gt)[i].T_W_B;
    EXPECT_DOUBLE_EQ((*gt)[i].t, (*raw)[i].t / 30.0);
    EXPECT_NEAR(b.translation().y(), -a.translation().y(), 1e-12);
    EXPECT_NEAR(b.translation().x(), a.translation().x(), 1e-12);
    EXPECT_LT((b.rotation() - M * a.rotation() * M).norm(), 1e-9);
    EXPECT_NEAR(b.rotation().determinant(), 1.0, 1e-9);  // still a rotation
  }
  // Relative motions keep their length: the mirror is an isometry.
  for (std::size_t i = 1; i < gt->size(); i += 97) {
    const double da = ((*raw)[i].T_W_B.inverse() * (*raw)[i - 1].T_W_B).translation().norm();
    const double db = ((*gt)[i].T_W_B.inverse() * (*gt)[i - 1].T_W_B).translation().norm();
    EXPECT_NEAR(da, db, 1e-12);
  }
  // eval reads the *.gt.freiburg name, and the dataset folder, the same way.
  auto e = eval::readTrajectoryForEval(file);
  ASSERT_TRUE(e.ok()) << e.error();
  EXPECT_EQ(e->size(), gt->size());
  EXPECT_NEAR((*e)[7].T_W_B.translation().y(), (*gt)[7].T_W_B.translation().y(), 1e-15);
  auto d = eval::readTrajectoryForEval(kIcl);
  ASSERT_TRUE(d.ok()) << d.error();
  EXPECT_EQ(d->size(), gt->size());
}

TEST(IclNuimLayout, TumOrderAndBadRowsInAssociations) {
  const fs::path dir = freshDir("assoc");
  fs::create_directory_symlink(fs::path(kIcl) / "rgb", dir / "rgb");
  fs::create_directory_symlink(fs::path(kIcl) / "depth", dir / "depth");
  // TUM's associate.py order (rgb first), real stamps in seconds: read as they are.
  std::ofstream(dir / "associations.txt") << "# t_rgb rgb t_depth depth\n"
                                           << "0.50 rgb/1.png 0.51 depth/1.png\n"
                                           << "0.60 rgb/2.png 0.61 depth/2.png\n"
                                           << "0.70 rgb/99999.png 0.71 depth/99999.png\n";
  auto ds = Dataset::open(dir.string());
  ASSERT_TRUE(ds.ok()) << ds.error();
  EXPECT_EQ((*ds)->size(), 2u);  // the row without images is skipped
  EXPECT_DOUBLE_EQ((*ds)->frameTime(1), 0.60);
  EXPECT_TRUE((*ds)->info().groundtruth.empty());
  std::ofstream(dir / "associations.txt") << "1 rgb/1.png 1 rgb/2.png\n";
  auto bad = Dataset::open(dir.string());
  ASSERT_FALSE(bad.ok());
  EXPECT_TRUE(contains(bad.error(), "associations.txt:1")) << bad.error();
}
