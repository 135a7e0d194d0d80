#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "frontend_synthetic.h"
#include "hermes/agent/orb_extractor.h"
#include "hermes/agent/stereo_matcher.h"

using namespace hermes;

namespace {

double median(std::vector<double> v) {
  if (v.empty()) return 1e9;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

struct PairStats {
  int features = 0, matched = 0, gross = 0;
  double median_disp_err = 1e9, median_depth_err = 1e9;
};

PairStats runPair(const std::string& image, double depth) {
  PairStats st;
  cv::Mat tex = test::loadSampleGrey(image);
  if (tex.empty()) return st;
  // EuRoC-like rig: fx = 458.654 px, b = 0.110 m.
  auto pair = test::makeFrontoParallelPair(tex, depth, 0.110, 458.654);
  OrbExtractor ex;
  auto l = ex.extract(pair.left);
  auto r = ex.extract(pair.right);
  if (!l.ok() || !r.ok()) return st;
  auto res = matchStereo(&*l, *r, pair.K, pair.baseline, StereoParams());
  if (!res.ok()) return st;
  st.features = int(l->size());
  st.matched = res->matched;
  std::vector<double> de, ze;
  for (size_t i = 0; i < l->size(); ++i) {
    if (l->keypoints[i].depth <= 0) continue;
    const double e = std::abs(res->disparity[i] - pair.disparity);
    if (e > 1.0) ++st.gross;
    de.push_back(e);
    ze.push_back(std::abs(l->keypoints[i].depth - depth));
  }
  st.median_disp_err = median(de);
  st.median_depth_err = median(ze);
  return st;
}

}  // namespace

TEST(StereoMatcher, SubPixelDisparityOnWarpedPlane) {
  for (auto [image, depth] : {std::pair<const char*, double>{"graf1.png", 2.0},
                              {"building.jpg", 3.3}}) {
    PairStats st = runPair(image, depth);
    ASSERT_GT(st.features, 0) << image << " missing or extraction failed";
    std::printf("%s depth %.2f m: %d/%d matched, gross %d, median |dd| %.4f px, median |dz| %.4f m\n",
                image, depth, st.matched, st.features, st.gross, st.median_disp_err,
                st.median_depth_err);
    EXPECT_GT(st.matched, st.features / 3) << image;
    EXPECT_LT(st.gross, std::max(3, st.matched / 50)) << image;
    EXPECT_LT(st.median_disp_err, 0.1) << image;
    // dz = z^2 / (fx b) * dd
    EXPECT_LT(st.median_depth_err, depth * depth / (458.654 * 0.110) * 0.1) << image;
  }
}

TEST(StereoMatcher, RefinementRecoversKnownShift) {
  cv::Mat tex = test::loadSampleGrey("graf1.png");
  ASSERT_FALSE(tex.empty());
  std::vector<double> err;
  for (double frac : {0.0, 0.13, 0.25, 0.5, 0.71, 0.9}) {
    auto pair = test::makeFrontoParallelPair(tex, 2.0, 0.110 * (20 + frac) / 25.2, 458.654);
    const double d = pair.disparity;
    for (int y = 60; y < 420; y += 40)
      for (int x = 100; x < 700; x += 50) {
        double xr = 0, cost = 0;
        if (!refineDisparitySad(pair.left, pair.right, x, y, int(std::lround(x - d)) + 1, 5, 5,
                                &xr, &cost))
          continue;
        err.push_back(std::abs((x - xr) - d));
      }
  }
  ASSERT_GT(err.size(), 300u);
  EXPECT_LT(median(err), 0.1);
}

TEST(StereoMatcher, IntegerSadEqualsTheZeroMeanDefinition) {
  // The cost is summed in integers; it must equal sum |(l - mean_l) - (r - mean_r)|
  // over the patch, evaluated here directly in floating point, and the returned
  // column must be the sub-pixel fit around the reference minimum (shifts whose
  // reference costs tie are skipped: either is a valid minimum).
  cv::Mat tex = test::loadSampleGrey("graf1.png");
  ASSERT_FALSE(tex.empty());
  auto pair = test::makeFrontoParallelPair(tex, 2.0, 0.110, 458.654);
  const cv::Mat &L = pair.left, &R = pair.right;
  auto reference = [&](int xl, int y, int xr, int w) {
    double ml = 0, mr = 0;
    for (int dy = -w; dy <= w; ++dy)
      for (int dx = -w; dx <= w; ++dx) {
        ml += L.at<uchar>(y + dy, xl + dx);
        mr += R.at<uchar>(y + dy, xr + dx);
      }
    ml /= (2 * w + 1) * (2 * w + 1);
    mr /= (2 * w + 1) * (2 * w + 1);
    double sad = 0;
    for (int dy = -w; dy <= w; ++dy)
      for (int dx = -w; dx <= w; ++dx)
        sad += std::abs((L.at<uchar>(y + dy, xl + dx) - ml) - (R.at<uchar>(y + dy, xr + dx) - mr));
    return sad;
  };
  int checked = 0;
  for (int w : {2, 5}) {
    const int radius = 4;
    for (int y = 40; y < 440; y += 23)
      for (int x = 80; x < 680; x += 37) {
        const int xr0 = x - int(std::lround(pair.disparity)) + (x + y) % 3 - 1;
        std::vector<double> c;
        for (int k = -radius - 1; k <= radius + 1; ++k) c.push_back(reference(x, y, xr0 + k, w));
        const auto best = std::min_element(c.begin() + 1, c.end() - 1) - c.begin();
        if (std::count_if(c.begin() + 1, c.end() - 1,
                          [&](double v) { return std::abs(v - c[best]) < 1e-6; }) > 1)
          continue;
        double xr = 0, cost = 0;
        const bool ok = refineDisparitySad(L, R, x, y, xr0, w, radius, &xr, &cost);
        if (best == 1 || best == 2 * radius + 1) {
          EXPECT_FALSE(ok);
          continue;
        }
        const double cm = c[best - 1], c0 = c[best], cp = c[best + 1];
        const double rise = std::max(cm, cp) - c0;
        const double delta = rise > 0 ? 0.5 * (cm - cp) / rise : 0.0;
        ASSERT_EQ(ok, std::abs(delta) <= 1.0) << x << "," << y;
        if (!ok) continue;
        EXPECT_NEAR(cost, c0, 1e-6 * std::max(1.0, c0));
        EXPECT_NEAR(xr, xr0 + (best - radius - 1) + delta, 1e-9);
        ++checked;
      }
  }
  EXPECT_GT(checked, 300);
}

TEST(StereoMatcher, RejectsInconsistentInputs) {
  cv::Mat tex = test::loadSampleGrey("graf1.png");
  ASSERT_FALSE(tex.empty());
  auto pair = test::makeFrontoParallelPair(tex, 2.0, 0.11, 458.654);
  OrbExtractor ex;
  OrbParams p4;
  p4.num_levels = 4;
  auto l = ex.extract(pair.left);
  auto r4 = OrbExtractor(p4).extract(pair.right);
  ASSERT_TRUE(l.ok() && r4.ok());
  EXPECT_FALSE(matchStereo(&*l, *r4, pair.K, 0.11, StereoParams()).ok());
  EXPECT_FALSE(matchStereo(&*l, *l, pair.K, 0.0, StereoParams()).ok());
  StereoParams bad;
  bad.min_depth = 5;
  bad.max_depth = 1;
  EXPECT_FALSE(bad.validate().ok());
}
