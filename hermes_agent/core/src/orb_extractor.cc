#include "hermes/agent/orb_extractor.h"

#include <algorithm>
#include <cmath>

#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

namespace hermes {

namespace {
constexpr int kPatchSize = 31;               // rBRIEF patch edge [px]
constexpr int kHalfPatch = kPatchSize / 2;   // orientation patch radius [px]
constexpr int kFastMargin = 3;               // FAST needs 3 px around a corner
}  // namespace

Status OrbParams::read(const Config& c, const std::string& p) {
  for (auto [key, ptr] : {std::pair<const char*, int*>{"num_features", &num_features},
                          {"num_levels", &num_levels},
                          {"fast_threshold", &fast_threshold},
                          {"fast_min_threshold", &fast_min_threshold},
                          {"cell_size", &cell_size},
                          {"edge_threshold", &edge_threshold}}) {
    Status s = c.get(p + "." + key, ptr);
    if (!s) return s;
  }
  Status s = c.get(p + ".scale_factor", &scale_factor);
  if (!s) return s;
  return validate();
}

void OrbParams::write(ConfigWriter* w, const std::string& p) const {
  w->set(p + ".num_features", num_features);
  w->set(p + ".num_levels", num_levels);
  w->set(p + ".scale_factor", scale_factor);
  w->set(p + ".fast_threshold", fast_threshold);
  w->set(p + ".fast_min_threshold", fast_min_threshold);
  w->set(p + ".cell_size", cell_size);
  w->set(p + ".edge_threshold", edge_threshold);
}

Status OrbParams::validate() const {
  if (num_features < 1) return Error{"orb.num_features must be >= 1"};
  if (num_levels < 1 || num_levels > 16) return Error{"orb.num_levels must be in [1, 16]"};
  if (!(scale_factor > 1.0 && scale_factor < 4.0))
    return Error{"orb.scale_factor must be in (1, 4)"};
  if (fast_threshold < 1 || fast_threshold > 255)
    return Error{"orb.fast_threshold must be in [1, 255]"};
  if (fast_min_threshold < 1 || fast_min_threshold > fast_threshold)
    return Error{"orb.fast_min_threshold must be in [1, fast_threshold]"};
  if (cell_size < 8) return Error{"orb.cell_size must be >= 8 px"};
  if (edge_threshold < kHalfPatch + 3)
    return Error{"orb.edge_threshold must be >= " + std::to_string(kHalfPatch + 3) +
                 " px (descriptor patch)"};
  return Status::Ok();
}

cv::Point2d FeatureSet::levelRatio(int level) const {
  if (level <= 0) return {1.0, 1.0};
  if (std::size_t(level) < pyramid.size() && !pyramid[0].empty() && !pyramid[level].empty())
    return {double(pyramid[0].cols) / pyramid[level].cols,
            double(pyramid[0].rows) / pyramid[level].rows};
  const double s = std::size_t(level) < scales.size() ? scales[level] : 1.0;
  return {s, s};
}

cv::Point2d FeatureSet::toBase(int level, double x, double y) const {
  const cv::Point2d r = levelRatio(level);
  return {(x + 0.5) * r.x - 0.5, (y + 0.5) * r.y - 0.5};
}

cv::Point2d FeatureSet::toLevel(int level, double u, double v) const {
  const cv::Point2d r = levelRatio(level);
  return {(u + 0.5) / r.x - 0.5, (v + 0.5) / r.y - 0.5};
}

std::vector<cv::Mat> buildPyramid(const cv::Mat& grey, int levels, double scale) {
  std::vector<cv::Mat> pyr(levels);
  pyr[0] = grey;
  double s = 1.0;
  for (int l = 1; l < levels; ++l) {
    s *= scale;
    const cv::Size sz(cvRound(grey.cols / s), cvRound(grey.rows / s));
    cv::resize(pyr[l - 1], pyr[l], sz, 0, 0, cv::INTER_LINEAR);
  }
  return pyr;
}

OrbExtractor::OrbExtractor(const OrbParams& params) : params_(params) {
  Status s = params_.validate();
  HERMES_CHECK(s.ok(), s.error());
  const int L = params_.num_levels;
  scales_.resize(L);
  scales_[0] = 1.f;
  for (int l = 1; l < L; ++l) scales_[l] = scales_[l - 1] * float(params_.scale_factor);
  // Budget proportional to each level's linear size (geometric series).
  const double f = 1.0 / params_.scale_factor;
  double n = params_.num_features * (1.0 - f) / (1.0 - std::pow(f, L));
  budget_.assign(L, 0);
  int assigned = 0;
  for (int l = 0; l + 1 < L; ++l) {
    budget_[l] = std::max(0, int(std::lround(n)));
    assigned += budget_[l];
    n *= f;
  }
  budget_[L - 1] = std::max(0, params_.num_features - assigned);
  // Single-level rBRIEF engine (the octave is handled by the level image given).
  describer_ = cv::ORB::create(params_.num_features, float(params_.scale_factor), 1,
                               params_.edge_threshold, 0, 2, cv::ORB::FAST_SCORE, kPatchSize,
                               params_.fast_threshold);
  // Circular patch: for row offset v, columns |u| <= umax[v].
  umax_.resize(kHalfPatch + 1);
  for (int v = 0; v <= kHalfPatch; ++v)
    umax_[v] = int(std::floor(std::sqrt(double(kHalfPatch * kHalfPatch - v * v)) + 1e-9));
}

namespace {

/// Orientation by intensity centroid over the circular patch around (x, y).
float centroidAngle(const cv::Mat& img, int x, int y, const std::vector<int>& umax) {
  long m01 = 0, m10 = 0;
  const int r = int(umax.size()) - 1;
  for (int v = -r; v <= r; ++v) {
    const uchar* row = img.ptr<uchar>(y + v);
    const int w = umax[std::abs(v)];
    long sum_row = 0;
    for (int u = -w; u <= w; ++u) {
      const int val = row[x + u];
      m10 += long(u) * val;
      sum_row += val;
    }
    m01 += long(v) * sum_row;
  }
  float a = float(cv::fastAtan2(float(m01), float(m10)));  // degrees [0, 360)
  return a >= 360.f ? a - 360.f : a;
}

/// Keeps up to `budget` keypoints spread over a grid of buckets: the strongest
/// of every bucket first, then the second strongest of every bucket, and so on.
std::vector<cv::KeyPoint> distributeByBuckets(std::vector<cv::KeyPoint> kps, int budget,
                                              int x0, int y0, int w, int h) {
  if (int(kps.size()) <= budget) return kps;
  const double side = std::sqrt(double(w) * h / std::max(budget, 1));
  const int bx = std::max(1, int(std::lround(w / side)));
  const int by = std::max(1, int(std::lround(h / side)));
  std::vector<std::vector<cv::KeyPoint>> buckets(bx * by);
  for (const auto& k : kps) {
    const int cx = std::clamp(int((k.pt.x - x0) * bx / w), 0, bx - 1);
    const int cy = std::clamp(int((k.pt.y - y0) * by / h), 0, by - 1);
    buckets[cy * bx + cx].push_back(k);
  }
  auto stronger = [](const cv::KeyPoint& a, const cv::KeyPoint& b) {
    return a.response > b.response;
  };
  for (auto& b : buckets) std::sort(b.begin(), b.end(), stronger);
  std::vector<cv::KeyPoint> out;
  out.reserve(budget);
  for (std::size_t rank = 0; int(out.size()) < budget; ++rank) {
    std::vector<cv::KeyPoint> tier;
    for (const auto& b : buckets)
      if (rank < b.size()) tier.push_back(b[rank]);
    if (tier.empty()) break;
    const int room = budget - int(out.size());
    if (int(tier.size()) > room) {
      std::partial_sort(tier.begin(), tier.begin() + room, tier.end(), stronger);
      tier.resize(room);
    }
    out.insert(out.end(), tier.begin(), tier.end());
  }
  return out;
}

}  // namespace

void OrbExtractor::detectLevel(const cv::Mat& img, int octave,
                               std::vector<cv::KeyPoint>* out) const {
  const int border = params_.edge_threshold;
  const int x0 = border, y0 = border;
  const int w = img.cols - 2 * border, h = img.rows - 2 * border;
  if (w <= 0 || h <= 0 || budget_[octave] == 0) return;
  const int ncols = std::max(1, w / params_.cell_size);
  const int nrows = std::max(1, h / params_.cell_size);
  auto colOf = [&](float x) {
    int c = std::clamp(int((x - x0) * ncols / w), 0, ncols - 1);
    while (c > 0 && x < x0 + c * w / ncols) --c;
    while (c + 1 < ncols && x >= x0 + (c + 1) * w / ncols) ++c;
    return c;
  };
  auto rowOf = [&](float y) {
    int r = std::clamp(int((y - y0) * nrows / h), 0, nrows - 1);
    while (r > 0 && y < y0 + r * h / nrows) --r;
    while (r + 1 < nrows && y >= y0 + (r + 1) * h / nrows) ++r;
    return r;
  };
  // Adaptive threshold per cell: one FAST pass over the level at the high
  // threshold (reaching kFastMargin px into the border so that corners on the
  // edge of the detection area can be scored); cells left without a corner are
  // searched again at the low threshold, each horizontal run of such cells in
  // one FAST call (a call per cell costs twice as much: OpenCV's FAST runs
  // 16 columns at a time and falls back to per-pixel code on narrow images).
  // The FAST score does not depend on the threshold, so the high-threshold
  // corners are those of a low-threshold pass with score >= fast_threshold;
  // non-maximum suppression sees the whole level (or run), not single cells.
  const cv::Rect roi(x0 - kFastMargin, y0 - kFastMargin, w + 2 * kFastMargin,
                     h + 2 * kFastMargin);
  std::vector<cv::KeyPoint> found, all;
  cv::FAST(img(roi), found, params_.fast_threshold, true);
  std::vector<char> has(size_t(ncols) * nrows, 0);
  all.reserve(found.size() + 64);
  for (auto& k : found) {
    k.pt.x += float(roi.x);
    k.pt.y += float(roi.y);
    if (k.pt.x < x0 || k.pt.y < y0 || k.pt.x >= x0 + w || k.pt.y >= y0 + h) continue;
    has[size_t(rowOf(k.pt.y)) * ncols + colOf(k.pt.x)] = 1;
    all.push_back(k);
  }
  for (int r = 0; r < nrows; ++r) {
    const int cy0 = y0 + r * h / nrows, cy1 = y0 + (r + 1) * h / nrows;
    for (int c = 0; c < ncols;) {
      if (has[size_t(r) * ncols + c]) {
        ++c;
        continue;
      }
      int c_end = c + 1;  // run of empty cells [c, c_end)
      while (c_end < ncols && !has[size_t(r) * ncols + c_end]) ++c_end;
      const int cx0 = x0 + c * w / ncols, cx1 = x0 + c_end * w / ncols;
      const cv::Rect run(cx0 - kFastMargin, cy0 - kFastMargin, cx1 - cx0 + 2 * kFastMargin,
                         cy1 - cy0 + 2 * kFastMargin);
      found.clear();
      cv::FAST(img(run), found, params_.fast_min_threshold, true);
      for (auto& k : found) {
        k.pt.x += float(run.x);
        k.pt.y += float(run.y);
        if (k.pt.x >= cx0 && k.pt.x < cx1 && k.pt.y >= cy0 && k.pt.y < cy1) all.push_back(k);
      }
      c = c_end;
    }
  }
  *out = distributeByBuckets(std::move(all), budget_[octave], x0, y0, w, h);
}

Expected<FeatureSet> OrbExtractor::extract(const cv::Mat& image) const {
  if (image.empty()) return Error{"ORB extraction: empty image"};
  cv::Mat grey;
  if (image.type() == CV_8UC1) {
    grey = image;
  } else if (image.type() == CV_8UC3) {
    cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  } else {
    return Error{"ORB extraction: image type " + std::to_string(image.type()) +
                 " is not 8-bit grey or BGR"};
  }
  const int min_side = 2 * params_.edge_threshold + params_.cell_size;
  if (grey.cols < min_side || grey.rows < min_side)
    return Error{"ORB extraction: image " + std::to_string(grey.cols) + "x" +
                 std::to_string(grey.rows) + " smaller than " + std::to_string(min_side) +
                 " px (border + one cell)"};

  FeatureSet fs;
  fs.width = grey.cols;
  fs.height = grey.rows;
  fs.scales = scales_;
  fs.pyramid = buildPyramid(grey, params_.num_levels, params_.scale_factor);

  // Per level: detection, orientation on the level image, then rBRIEF (OpenCV's
  // ORB descriptor on our keypoints, orientation as given) on the same level
  // image, so the pyramid is built once (cv::ORB::compute on the full image would
  // rebuild all levels). Keypoints are given to it in level coordinates; the
  // descriptor centre is the same integer pixel as a level-0 call would use.
  // (cv::ORB resamples its own levels with INTER_LINEAR_EXACT, ours are
  // INTER_LINEAR: on levels >= 1 about 1.3 of 256 bits differ from that path.)
  // cv::ORB drops keypoints too close to the border, so results are
  // re-associated by class_id.
  std::vector<cv::KeyPoint> level_kps, described;
  std::vector<int> row_of;  // level keypoint -> descriptor row (-1: dropped)
  cv::Mat desc;
  fs.keypoints.reserve(params_.num_features);
  fs.descriptors.reserve(params_.num_features);
  fs.angles.reserve(params_.num_features);
  fs.responses.reserve(params_.num_features);
  for (int l = 0; l < params_.num_levels; ++l) {
    level_kps.clear();
    detectLevel(fs.pyramid[l], l, &level_kps);
    if (level_kps.empty()) continue;
    // Orientation and descriptors are computed top to bottom (patches then walk
    // the image row by row instead of jumping between buckets); the output
    // keeps the bucket order.
    for (std::size_t i = 0; i < level_kps.size(); ++i) {
      cv::KeyPoint& k = level_kps[i];
      k.octave = 0;  // level coordinates for the single-level descriptor call
      k.size = float(kPatchSize);
      k.class_id = int(i);
    }
    described = level_kps;
    std::stable_sort(described.begin(), described.end(),
                     [](const cv::KeyPoint& a, const cv::KeyPoint& b) { return a.pt.y < b.pt.y; });
    for (cv::KeyPoint& k : described) {
      k.angle = centroidAngle(fs.pyramid[l], int(k.pt.x), int(k.pt.y), umax_);
      level_kps[k.class_id].angle = k.angle;
    }
    describer_->compute(fs.pyramid[l], described, desc);
    row_of.assign(level_kps.size(), -1);
    for (std::size_t i = 0; i < described.size(); ++i) row_of[described[i].class_id] = int(i);
    for (std::size_t i = 0; i < level_kps.size(); ++i) {
      if (row_of[i] < 0) continue;
      const cv::KeyPoint& src = level_kps[i];
      Keypoint k;
      const cv::Point2d base = fs.toBase(l, src.pt.x, src.pt.y);
      k.u = float(base.x);
      k.v = float(base.y);
      k.octave = std::uint8_t(l);
      fs.keypoints.push_back(k);
      Descriptor d;
      const uchar* row = desc.ptr<uchar>(row_of[i]);
      std::copy(row, row + 32, d.begin());
      fs.descriptors.push_back(d);
      fs.angles.push_back(src.angle);
      fs.responses.push_back(src.response);
    }
  }
  return fs;
}

void undistortKeypoints(const PinholeRadtan& camera, const PinholeIntrinsics& out,
                        FeatureSet* features) {
  for (auto& k : features->keypoints) {
    const Vec2 uv = camera.undistortPixel(Vec2(k.u, k.v), out);
    k.u = float(uv.x());
    k.v = float(uv.y());
  }
}

}  // namespace hermes
