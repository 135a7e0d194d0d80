// Time windows of a EuRoC folder (the swarm sweep's robots): rows kept by
// stamp relative to cam0's first, everything else linked, errors named.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include <unistd.h>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "hermes/core/render/settings.h"
#include "hermes/core/render_cache.h"
#include "hermes/system/dataset_window.h"

namespace fs = std::filesystem;

namespace hermes::system {
namespace {

/// A EuRoC-shaped folder: cam0/cam1 with 100 rows at 10 Hz from t0, a sensor.yaml
/// each, a ground-truth folder.
fs::path makeSource(const fs::path& root) {
  const fs::path mav0 = root / "src" / "mav0";
  for (const char* cam : {"cam0", "cam1"}) {
    fs::create_directories(mav0 / cam / "data");
    std::ofstream(mav0 / cam / "sensor.yaml") << "sensor_type: camera\n";
    std::ofstream csv(mav0 / cam / "data.csv");
    csv << "#timestamp [ns],filename\n";
    for (int i = 0; i < 100; ++i) {
      const long long ns = 1403636580000000000LL + 100000000LL * i;
      csv << ns << ',' << ns << ".png\n";
    }
  }
  fs::create_directories(mav0 / "state_groundtruth_estimate0");
  std::ofstream(mav0 / "state_groundtruth_estimate0" / "data.csv") << "#t\n";
  return root / "src";
}

int rows(const fs::path& csv) {
  std::ifstream f(csv);
  int n = 0;
  for (std::string line; std::getline(f, line);) n += !line.empty() && line[0] != '#';
  return n;
}

TEST(DatasetWindow, KeepsTheWindowsRowsAndLinksTheRest) {
  const fs::path root = fs::temp_directory_path() / ("hermes_window_" + std::to_string(::getpid()));
  fs::remove_all(root);
  const fs::path src = makeSource(root);
  auto w = writeEurocWindow(src.string(), 2.0, 3.0, (root / "view").string());
  ASSERT_TRUE(w.ok()) << w.error();
  EXPECT_EQ(w->frames, 30u);  // t = 2.0 .. 4.9 s
  EXPECT_NEAR(w->first_stamp_s, 1403636582.0, 1e-6);
  const fs::path mav0 = root / "view" / "mav0";
  EXPECT_EQ(rows(mav0 / "cam0" / "data.csv"), 30);
  EXPECT_EQ(rows(mav0 / "cam1" / "data.csv"), 30);
  EXPECT_TRUE(fs::is_symlink(mav0 / "cam0" / "data"));
  EXPECT_TRUE(fs::is_symlink(mav0 / "cam1" / "sensor.yaml"));
  EXPECT_TRUE(fs::is_symlink(mav0 / "state_groundtruth_estimate0"));
  // Written again over an existing view.
  w = writeEurocWindow(src.string(), 0.0, 1.0, (root / "view").string());
  ASSERT_TRUE(w.ok()) << w.error();
  EXPECT_EQ(rows(mav0 / "cam0" / "data.csv"), 10);
  fs::remove_all(root);
}

TEST(DatasetWindow, ErrorsNameTheProblem) {
  const fs::path root = fs::temp_directory_path() / ("hermes_window_bad_" + std::to_string(::getpid()));
  fs::remove_all(root);
  const fs::path src = makeSource(root);
  auto empty = writeEurocWindow(src.string(), 50.0, 5.0, (root / "view").string());
  ASSERT_FALSE(empty.ok());
  EXPECT_NE(empty.error().find("no frame"), std::string::npos) << empty.error();
  auto missing = writeEurocWindow((root / "nothing").string(), 0.0, 5.0, (root / "view").string());
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.error().find("cam0/data.csv"), std::string::npos) << missing.error();
  auto bad = writeEurocWindow(src.string(), 0.0, 0.0, (root / "view").string());
  EXPECT_FALSE(bad.ok());
  fs::remove_all(root);
}

// A camera gone dark in a view: black files for the stretch, links for the rest,
// the source untouched; a stretch without frames and a second pass are refused.
TEST(DatasetWindow, BlackOutDarkensTheViewNotTheSource) {
  const fs::path root = fs::temp_directory_path() / ("hermes_window_dark_" + std::to_string(::getpid()));
  fs::remove_all(root);
  const fs::path src = makeSource(root);
  const cv::Mat grey(6, 8, CV_8UC1, cv::Scalar(100));
  for (const char* cam : {"cam0", "cam1"})
    for (int i = 0; i < 100; ++i)
      ASSERT_TRUE(cv::imwrite((src / "mav0" / cam / "data" /
                               (std::to_string(1403636580000000000LL + 100000000LL * i) + ".png")).string(), grey));
  const fs::path view = root / "view";
  ASSERT_TRUE(writeEurocWindow(src.string(), 2.0, 3.0, view.string()).ok());
  auto none = blackOutFrames(view.string(), 10.0, 11.0);
  ASSERT_FALSE(none.ok());
  EXPECT_NE(none.error().find("no frame"), std::string::npos) << none.error();
  ASSERT_TRUE(writeEurocWindow(src.string(), 2.0, 3.0, view.string()).ok());
  auto after = blackOutFrames(view.string(), 1.0, 1.5);  // t = 3.0 .. 3.4 s of the source
  ASSERT_TRUE(after.ok()) << after.error();
  EXPECT_NEAR(*after, 1403636583.5, 1e-6);
  for (const char* cam : {"cam0", "cam1"}) {
    const fs::path images = view / "mav0" / cam / "data";
    EXPECT_FALSE(fs::is_symlink(images));
    int dark = 0, linked = 0;
    for (const auto& e : fs::directory_iterator(images)) {
      if (fs::is_symlink(e.path())) {
        ++linked;
        continue;
      }
      ++dark;
      EXPECT_EQ(cv::countNonZero(cv::imread(e.path().string(), cv::IMREAD_UNCHANGED)), 0) << e.path();
    }
    EXPECT_EQ(dark, 5) << cam;
    EXPECT_EQ(linked, 25) << cam;
  }
  const cv::Mat source = cv::imread((src / "mav0" / "cam0" / "data" / "1403636583000000000.png").string(),
                                    cv::IMREAD_UNCHANGED);
  EXPECT_EQ(cv::countNonZero(source), 48) << "the source stays as it was";
  auto again = blackOutFrames(view.string(), 0.0, 1.0);
  ASSERT_FALSE(again.ok());
  EXPECT_NE(again.error().find("link"), std::string::npos) << again.error();
  fs::remove_all(root);
}

/// A finished whole-sequence render of one robot, made with `settings`.
void fakeRender(const fs::path& data, const std::vector<std::string>& settings) {
  fs::create_directories(data / "V1_01_easy" / "mav0");
  RenderRequest req;
  req.settings = settings;
  auto fingerprint = renderFingerprint(req);
  ASSERT_TRUE(fingerprint.ok()) << fingerprint.error();
  std::ofstream(data / "render_config.yaml") << *fingerprint;
  std::ofstream(data / "done") << "ok\n";
}

// A render made with other settings is not taken for the one asked for (here
// it would be rendered again, and this test binary has no hermes_sim beside
// it: the error names it). Without settings a request is realistic.
TEST(WholeRenders, ARenderIsUsedOnlyWithTheSettingsItWasMadeWith) {
  const fs::path root = fs::temp_directory_path() / ("hermes_whole_" + std::to_string(::getpid()));
  fs::remove_all(root);
  fs::create_directories(root / "gt");
  std::ofstream(root / "gt" / "V1_01_easy.txt") << "0 0 0 0 0 0 0 1\n1 1 0 0 0 0 0 1\n";
  const std::vector<std::string> seqs = {"V1_01_easy"};
  const std::vector<std::string> plain = {render::kPlainLook};
  const std::vector<std::string> realistic = {"render.realistic=true"};
  const std::string gt = (root / "gt").string();
  fakeRender(root / "plain", plain);
  EXPECT_TRUE(ensureWholeRenders((root / "plain").string(), seqs, gt, 20, plain).ok());
  for (const std::vector<std::string>& other : {realistic, std::vector<std::string>{}}) {
    Status s = ensureWholeRenders((root / "plain").string(), seqs, gt, 20, other);
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.error().find("hermes_sim"), std::string::npos) << s.error();
  }
  fakeRender(root / "realistic", {});  // the default look is the realistic one
  Status s = ensureWholeRenders((root / "realistic").string(), seqs, gt, 20, realistic);
  EXPECT_TRUE(s.ok()) << s.error();
  EXPECT_FALSE(ensureWholeRenders((root / "realistic").string(), seqs, gt, 20, plain).ok());
  s = ensureWholeRenders((root / "realistic").string(), seqs, gt, 20, {"render.realistic=maybe"});
  EXPECT_FALSE(s.ok());  // a bad setting is named, nothing rendered
  // A plain render from before render_config.yaml existed: complete sequences count
  // for the plain look only.
  fs::create_directories(root / "old" / "V1_01_easy" / "mav0");
  EXPECT_TRUE(ensureWholeRenders((root / "old").string(), seqs, gt, 20, plain).ok());
  EXPECT_FALSE(ensureWholeRenders((root / "old").string(), seqs, gt, 20).ok());
  fs::remove_all(root);
}

}  // namespace
}  // namespace hermes::system
