// hermes_sim end to end: ~1 s of MH_01 at a low rate and resolution into a temp
// dir, EuRoC and TUM layouts present and parseable; bad arguments exit with 2.
#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <yaml-cpp/yaml.h>

namespace fs = std::filesystem;

namespace {
std::string simBinary() {
  return (fs::read_symlink("/proc/self/exe").parent_path().parent_path() / "bin" / "hermes_sim").string();
}
const std::string kGt = std::string(HERMES_TRAJECTORY_DIR) + "/MH_01_easy.txt";

int run(const std::string& args) {
  const int rc = std::system((simBinary() + " " + args + " 2>/dev/null").c_str());
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

std::vector<std::string> lines(const std::string& path) {
  std::ifstream f(path);
  std::vector<std::string> out;
  for (std::string l; std::getline(f, l);)
    if (!l.empty() && l[0] != '#') out.push_back(l);
  return out;
}
}  // namespace

TEST(RenderCli, EurocLayout) {
  ASSERT_TRUE(fs::exists(simBinary())) << "build hermes_sim first: " << simBinary();
  const std::string out = ::testing::TempDir() + "/render_cli_euroc";
  fs::remove_all(out);
  ASSERT_EQ(run("--trajectory " + kGt + " --out " + out + " --duration 1 --rate 4 --width 188 --height 120"), 0);
  const std::string mav = out + "/MH_01_easy/mav0";
  EXPECT_TRUE(fs::exists(out + "/scene.json"));
  EXPECT_TRUE(fs::exists(mav + "/body.yaml"));
  for (const std::string cam : {"cam0", "cam1"}) {
    const auto rows = lines(mav + "/" + cam + "/data.csv");
    ASSERT_EQ(rows.size(), 4u) << cam;
    for (const std::string& r : rows) {
      const auto comma = r.find(',');
      ASSERT_NE(comma, std::string::npos);
      EXPECT_EQ(r.substr(comma + 1), r.substr(0, comma) + ".png");
      const cv::Mat img = cv::imread(mav + "/" + cam + "/data/" + r.substr(comma + 1), cv::IMREAD_UNCHANGED);
      ASSERT_FALSE(img.empty());
      EXPECT_EQ(img.type(), CV_8UC1);
      EXPECT_EQ(img.cols, 188);
      EXPECT_EQ(img.rows, 120);
    }
    std::ifstream y(mav + "/" + cam + "/sensor.yaml");
    std::string first;
    std::getline(y, first);
    EXPECT_EQ(first, "%YAML:1.0");
    cv::FileStorage fsr(mav + "/" + cam + "/sensor.yaml", cv::FileStorage::READ);
    ASSERT_TRUE(fsr.isOpened());
    std::vector<double> intr, dist, T;
    fsr["intrinsics"] >> intr;
    fsr["distortion_coefficients"] >> dist;
    fsr["T_BS"]["data"] >> T;
    ASSERT_EQ(intr.size(), 4u);
    ASSERT_EQ(dist.size(), 4u);
    ASSERT_EQ(T.size(), 16u);
    EXPECT_NEAR(intr[0], cam == "cam0" ? 458.654 / 4 : 457.587 / 4, 1e-6);
    EXPECT_NEAR(dist[0], cam == "cam0" ? -0.28340811 : -0.28368365, 1e-9);
  }
  const auto gt = lines(mav + "/state_groundtruth_estimate0/data.csv");
  ASSERT_EQ(gt.size(), 4u);
  std::stringstream ss(gt[0]);
  std::vector<double> v;
  for (std::string c; std::getline(ss, c, ',');) v.push_back(std::stod(c));
  ASSERT_EQ(v.size(), 17u);
  EXPECT_NEAR(v[1], 4.688319, 1e-6);  // first MH_01 pose, start offset 0
  EXPECT_NEAR(v[4] * v[4] + v[5] * v[5] + v[6] * v[6] + v[7] * v[7], 1.0, 1e-6);
}

TEST(RenderCli, TumLayoutAndDeterminism) {
  const std::string a = ::testing::TempDir() + "/render_cli_tum_a";
  const std::string b = ::testing::TempDir() + "/render_cli_tum_b";
  fs::remove_all(a);
  fs::remove_all(b);
  const std::string args =
      "--trajectory " + kGt + " --format tum --start 30 --duration 0.5 --rate 4 --width 160 --height 120 --plain --out ";
  ASSERT_EQ(run(args + a), 0);
  ASSERT_EQ(run(args + b), 0);
  const YAML::Node cam = YAML::LoadFile(a + "/MH_01_easy/camera.yaml");
  for (const char* k : {"fx", "fy", "cx", "cy", "width", "height", "depth_scale"}) EXPECT_TRUE(cam[k]) << k;
  EXPECT_EQ(cam["depth_scale"].as<double>(), 5000.0);
  const auto rgb = lines(a + "/MH_01_easy/rgb.txt"), depth = lines(a + "/MH_01_easy/depth.txt");
  const auto gt = lines(a + "/MH_01_easy/groundtruth.txt");
  ASSERT_EQ(rgb.size(), 2u);
  ASSERT_EQ(depth.size(), 2u);
  ASSERT_EQ(gt.size(), 2u);
  const std::string dfile = depth[0].substr(depth[0].find(' ') + 1);
  const cv::Mat d = cv::imread(a + "/MH_01_easy/" + dfile, cv::IMREAD_UNCHANGED);
  ASSERT_EQ(d.type(), CV_16UC1);
  double mn, mx;
  cv::minMaxLoc(d, &mn, &mx);
  EXPECT_GT(mn, 0.3 * 5000);  // every pixel hits geometry beyond the clearance
  for (const std::string& f : {rgb[1].substr(rgb[1].find(' ') + 1), dfile}) {
    const cv::Mat ia = cv::imread(a + "/MH_01_easy/" + f, cv::IMREAD_UNCHANGED);
    const cv::Mat ib = cv::imread(b + "/MH_01_easy/" + f, cv::IMREAD_UNCHANGED);
    ASSERT_FALSE(ia.empty());
    EXPECT_EQ(cv::norm(ia, ib, cv::NORM_INF), 0.0) << f;
  }
}

namespace {
/// Mean absolute horizontal Sobel response of the first cam0 image under `dir`.
double firstImageGradient(const std::string& dir) {
  const auto rows = lines(dir + "/MH_01_easy/mav0/cam0/data.csv");
  if (rows.empty()) return -1;
  const cv::Mat img = cv::imread(dir + "/MH_01_easy/mav0/cam0/data/" + rows[0].substr(rows[0].find(',') + 1),
                                 cv::IMREAD_GRAYSCALE);
  if (img.empty()) return -1;
  cv::Mat gx;
  cv::Sobel(img, gx, CV_32F, 1, 0);
  return cv::mean(cv::abs(gx))[0];
}
}  // namespace

TEST(RenderCli, PoorFractionFlattensTheTexture) {
  // --poor-fraction 1 leaves every panel of the textured faces near-uniform: the
  // same view loses most of its image gradient; the value is recorded in scene.json.
  const std::string rich = ::testing::TempDir() + "/render_cli_rich";
  const std::string poor = ::testing::TempDir() + "/render_cli_poor";
  fs::remove_all(rich);
  fs::remove_all(poor);
  const std::string args = "--trajectory " + kGt + " --duration 0.25 --rate 4 --width 188 --height 120 --no-noise --plain";
  ASSERT_EQ(run(args + " --out " + rich), 0);
  ASSERT_EQ(run(args + " --poor-fraction 1 --out " + poor), 0);
  const double g_rich = firstImageGradient(rich), g_poor = firstImageGradient(poor);
  std::printf("mean |d/dx|: default %.2f, --poor-fraction 1 %.2f\n", g_rich, g_poor);
  ASSERT_GT(g_rich, 0);
  ASSERT_GE(g_poor, 0);
  EXPECT_LT(g_poor, 0.5 * g_rich);
  std::ifstream js(poor + "/scene.json");
  std::stringstream body;
  body << js.rdbuf();
  EXPECT_NE(body.str().find("\"poor_fraction\": 1.0"), std::string::npos);
  EXPECT_EQ(run(args + " --poor-fraction 1.5 --out " + poor), 2);
  EXPECT_EQ(run(args + " --poor-fraction x --out " + poor), 2);
}

TEST(RenderCli, BadArgumentsExitTwo) {
  EXPECT_EQ(run("--out /tmp/x"), 2);
  EXPECT_EQ(run("--trajectory /nonexistent.txt --out /tmp/x"), 2);
  EXPECT_EQ(run("--trajectory " + kGt + " --out /tmp/x --rate abc"), 2);
  EXPECT_EQ(run("--trajectory " + kGt + " --out /tmp/x --format png"), 2);
  EXPECT_EQ(run("--bogus"), 2);
  EXPECT_EQ(run("--help"), 0);
}

TEST(RenderCli, RealisticPresetAndSettingsAreRecorded) {
  // --realistic (the default) switches every effect on, --set overrides one, and the settings
  // used land in render_config.yaml (what the render cache compares).
  const std::string out = ::testing::TempDir() + "/render_cli_realistic";
  fs::remove_all(out);
  const std::string args = "--trajectory " + kGt + " --duration 0.25 --rate 4 --width 188 --height 120";
  ASSERT_EQ(run(args + " --realistic --set render.sensor.exposure_s=0.004 --out " + out), 0);
  const YAML::Node cfg = YAML::LoadFile(out + "/render_config.yaml");
  EXPECT_TRUE(cfg["render"]["realistic"].as<bool>());
  EXPECT_TRUE(cfg["render"]["sensor"]["motion_blur"].as<bool>());
  EXPECT_TRUE(cfg["render"]["sensor"]["photon_noise"].as<bool>());
  EXPECT_TRUE(cfg["render"]["scene"]["dark_regions"].as<bool>());
  EXPECT_TRUE(cfg["render"]["scene"]["aliasing"].as<bool>());
  EXPECT_DOUBLE_EQ(cfg["render"]["sensor"]["exposure_s"].as<double>(), 0.004);
  EXPECT_GT(firstImageGradient(out), 0);
  // Without a flag the render is realistic; --plain switches every effect off.
  const std::string plain = out + "_plain", dflt = out + "_default";
  fs::remove_all(plain);
  fs::remove_all(dflt);
  ASSERT_EQ(run(args + " --out " + dflt), 0);
  EXPECT_TRUE(YAML::LoadFile(dflt + "/render_config.yaml")["render"]["sensor"]["motion_blur"].as<bool>());
  ASSERT_EQ(run(args + " --plain --out " + plain), 0);
  const YAML::Node p = YAML::LoadFile(plain + "/render_config.yaml");
  EXPECT_FALSE(p["render"]["realistic"].as<bool>());
  EXPECT_FALSE(p["render"]["sensor"]["motion_blur"].as<bool>());
  EXPECT_FALSE(p["render"]["scene"]["dark_regions"].as<bool>());
  EXPECT_EQ(run(args + " --plain --realistic --out " + plain), 2);
  EXPECT_EQ(run(args + " --set render.sensor.no_such_key=1 --out " + out), 2);
  EXPECT_EQ(run(args + " --set render.sensor.exposure_s=1 --out " + out), 2);
  EXPECT_EQ(run(args + " --set exposure_s --out " + out), 2);
}

TEST(RenderCli, JobsDoNotChangeTheOutput) {
  // Two robots rendered one after the other and at once: the same bytes.
  const std::string gt2 = std::string(HERMES_TRAJECTORY_DIR) + "/MH_02_easy.txt";
  const std::string base = ::testing::TempDir() + "/render_cli_jobs";
  const std::string args = "--trajectory " + kGt + " --trajectory " + gt2 +
                           " --start 20 --duration 0.5 --rate 4 --width 188 --height 120 --out ";
  fs::remove_all(base + "1");
  fs::remove_all(base + "2");
  ASSERT_EQ(run(args + base + "1 --jobs 1"), 0);
  ASSERT_EQ(run(args + base + "2 --jobs 2"), 0);
  int compared = 0;
  for (const char* stem : {"MH_01_easy", "MH_02_easy"})
    for (const auto& e : fs::directory_iterator(base + "1/" + stem + "/mav0/cam1/data")) {
      const std::string other = base + "2/" + stem + "/mav0/cam1/data/" + e.path().filename().string();
      const cv::Mat a = cv::imread(e.path().string(), cv::IMREAD_UNCHANGED);
      const cv::Mat b = cv::imread(other, cv::IMREAD_UNCHANGED);
      ASSERT_FALSE(a.empty() || b.empty()) << other;
      EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0.0) << other;
      ++compared;
    }
  EXPECT_EQ(compared, 4);
  EXPECT_EQ(run(args + base + "2 --jobs 0"), 2);
}
