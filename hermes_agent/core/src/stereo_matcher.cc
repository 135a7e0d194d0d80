#include "hermes/agent/stereo_matcher.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace hermes {

Status StereoParams::read(const Config& c, const std::string& p) {
  for (auto [key, ptr] : {std::pair<const char*, int*>{"max_hamming", &max_hamming},
                          {"sad_half_window", &sad_half_window},
                          {"sad_search_radius", &sad_search_radius}}) {
    Status s = c.get(p + "." + key, ptr);
    if (!s) return s;
  }
  for (auto [key, ptr] : {std::pair<const char*, double*>{"ratio", &ratio},
                          {"row_band_px", &row_band_px},
                          {"min_depth", &min_depth},
                          {"max_depth", &max_depth},
                          {"sad_outlier_factor", &sad_outlier_factor}}) {
    Status s = c.get(p + "." + key, ptr);
    if (!s) return s;
  }
  Status s = c.getChoice(p + ".subpixel_fit", {"equiangular", "parabola"}, &subpixel_fit);
  if (!s) return s;
  return validate();
}

void StereoParams::write(ConfigWriter* w, const std::string& p) const {
  w->set(p + ".max_hamming", max_hamming);
  w->set(p + ".ratio", ratio);
  w->set(p + ".row_band_px", row_band_px);
  w->set(p + ".min_depth", min_depth);
  w->set(p + ".max_depth", max_depth);
  w->set(p + ".sad_half_window", sad_half_window);
  w->set(p + ".sad_search_radius", sad_search_radius);
  w->set(p + ".sad_outlier_factor", sad_outlier_factor);
  w->set(p + ".subpixel_fit", subpixel_fit);
}

Status StereoParams::validate() const {
  if (max_hamming < 0 || max_hamming > 256) return Error{"stereo.max_hamming must be in [0, 256]"};
  if (!(ratio > 0 && ratio <= 1)) return Error{"stereo.ratio must be in (0, 1]"};
  if (!(row_band_px >= 0)) return Error{"stereo.row_band_px must be >= 0"};
  if (!(min_depth > 0 && max_depth > min_depth))
    return Error{"stereo.min_depth/max_depth must satisfy 0 < min_depth < max_depth"};
  if (sad_half_window < 1 || sad_half_window > 15)
    return Error{"stereo.sad_half_window must be in [1, 15]"};
  if (sad_search_radius < 1 || sad_search_radius > 15)
    return Error{"stereo.sad_search_radius must be in [1, 15]"};
  if (!(sad_outlier_factor > 1)) return Error{"stereo.sad_outlier_factor must be > 1"};
  if (subpixel_fit != "equiangular" && subpixel_fit != "parabola")
    return Error{"stereo.subpixel_fit must be equiangular or parabola"};
  return Status::Ok();
}

bool refineDisparitySad(const cv::Mat& L, const cv::Mat& R, int xl, int y, int xr0, int w,
                        int radius, double* x_right, double* cost, bool parabola) {
  if (y - w < 0 || y + w >= L.rows || y + w >= R.rows) return false;
  if (xl - w < 0 || xl + w >= L.cols) return false;
  if (xr0 - w - radius - 1 < 0 || xr0 + w + radius + 1 >= R.cols) return false;
  constexpr int kMaxN = 31, kMaxPos = 2 * 15 + 3, kLanes = 8;  // w, radius <= 15
  HERMES_CHECK(w >= 1 && w <= 15 && radius >= 1 && radius <= 15,
               "refineDisparitySad: half window and radius must be in [1, 15]");
  const int n = 2 * w + 1, nn = n * n, npos = 2 * radius + 3;
  // Zero-mean patches make the cost insensitive to a brightness offset between
  // cameras. With S the patch sums, sum |(l - S_l/nn) - (r - S_r/nn)| equals
  // sum |(nn l - S_l) - (nn r - S_r)| / nn, which is summed exactly in integers.
  int a[kMaxN][kMaxN];
  int sum_l = 0;
  for (int dy = -w; dy <= w; ++dy) {
    const uchar* lr = L.ptr<uchar>(y + dy) + xl - w;
    for (int dx = 0; dx < n; ++dx) sum_l += lr[dx];
  }
  for (int dy = 0; dy < n; ++dy) {
    const uchar* lr = L.ptr<uchar>(y + dy - w) + xl - w;
    for (int dx = 0; dx < n; ++dx) a[dy][dx] = nn * lr[dx] - sum_l;
  }
  // The right band: shift i (0..npos-1, i.e. k = i - radius - 1) covers its
  // columns [i, i + n); nn r is stored padded so that kLanes shifts at a time
  // read contiguous memory (the padding lanes are computed and dropped).
  const int x_first = xr0 - radius - 1 - w, ncols = n + npos - 1;
  int rr[kMaxN][kMaxN + kMaxPos + kLanes];
  int col[kMaxN + kMaxPos] = {0};
  for (int dy = 0; dy < n; ++dy) {
    const uchar* row = R.ptr<uchar>(y + dy - w) + x_first;
    for (int x = 0; x < ncols; ++x) {
      rr[dy][x] = nn * row[x];
      col[x] += row[x];
    }
    for (int x = ncols; x < ncols + kLanes; ++x) rr[dy][x] = 0;
  }
  int sum_r[kMaxPos + kLanes] = {0};  // patch sum at each shift (sliding column sums)
  for (int x = 0; x < n; ++x) sum_r[0] += col[x];
  for (int i = 1; i < npos; ++i) sum_r[i] = sum_r[i - 1] + col[i + n - 1] - col[i - 1];
  double c[kMaxPos + kLanes];
  for (int i0 = 0; i0 < npos; i0 += kLanes) {
    int acc[kLanes] = {0};
    for (int dy = 0; dy < n; ++dy)
      for (int dx = 0; dx < n; ++dx) {
        const int av = a[dy][dx];
        const int* r = &rr[dy][i0 + dx];
        for (int j = 0; j < kLanes; ++j) acc[j] += std::abs(av + sum_r[i0 + j] - r[j]);
      }
    for (int j = 0; j < kLanes; ++j) c[i0 + j] = double(acc[j]) / nn;
  }
  // The minimum over [-radius, radius]; entries ±(radius+1) only serve the fit.
  int best = 1;
  for (int i = 1; i <= 2 * radius + 1; ++i)
    if (c[i] < c[best]) best = i;
  if (best == 1 || best == 2 * radius + 1) return false;  // on the search border
  const double cm = c[best - 1], c0 = c[best], cp = c[best + 1];
  // SAD grows linearly away from its minimum, so the symmetric "V" (equiangular)
  // fit is used: it is unbiased for that shape where the parabola locks onto
  // integer shifts (Shimizu & Okutomi 2005).
  double delta = 0.0;
  if (parabola) {
    const double den = cm - 2 * c0 + cp;
    delta = den > 0 ? 0.5 * (cm - cp) / den : 0.0;
  } else {
    const double rise = std::max(cm, cp) - c0;
    delta = rise > 0 ? 0.5 * (cm - cp) / rise : 0.0;
  }
  if (std::abs(delta) > 1.0) return false;
  *x_right = xr0 + (best - radius - 1) + delta;
  *cost = c0;
  return true;
}

Expected<StereoResult> matchStereo(FeatureSet* left, const FeatureSet& right,
                                   const PinholeIntrinsics& K, double baseline,
                                   const StereoParams& p) {
  if (!(baseline > 0)) return Error{"stereo matching: baseline must be > 0"};
  if (!(K.fx > 0)) return Error{"stereo matching: fx must be > 0"};
  if (left->pyramid.empty() || right.pyramid.size() != left->pyramid.size() ||
      right.scales.size() != left->scales.size())
    return Error{"stereo matching: left and right pyramids differ (same extractor needed)"};
  if (left->width != right.width || left->height != right.height)
    return Error{"stereo matching: left and right image sizes differ"};
  const int H = left->height;
  const bool parabola = p.subpixel_fit == "parabola";
  const double min_d = K.fx * baseline / p.max_depth;
  const double max_d = K.fx * baseline / p.min_depth;

  // Row index: every right keypoint is listed in all rows its band covers, in
  // one flat array (row y: row_index[row_start[y] .. row_start[y + 1]), j ascending).
  std::vector<int> row_start(H + 1, 0), row_index;
  auto bandOf = [&](const Keypoint& k) {
    const double r = p.row_band_px * right.scales[k.octave];
    return std::pair<int, int>(std::max(0, int(std::floor(k.v - r))),
                               std::min(H - 1, int(std::ceil(k.v + r))));
  };
  for (const Keypoint& k : right.keypoints) {
    const auto [y0, y1] = bandOf(k);
    for (int y = y0; y <= y1; ++y) ++row_start[y + 1];
  }
  for (int y = 0; y < H; ++y) row_start[y + 1] += row_start[y];
  row_index.resize(row_start[H]);
  {
    std::vector<int> fill(row_start.begin(), row_start.end() - 1);
    for (int j = 0; j < int(right.size()); ++j) {
      const auto [y0, y1] = bandOf(right.keypoints[j]);
      for (int y = y0; y <= y1; ++y) row_index[fill[y]++] = j;
    }
  }

  StereoResult out;
  const int n = int(left->size());
  out.u_right.assign(n, -1.f);
  out.disparity.assign(n, 0.f);
  std::vector<double> costs(n, -1.0);
  // Keypoints are visited top to bottom (each is matched on its own, so the
  // order changes no result): the SAD patches then walk the images row by row
  // instead of jumping between buckets.
  std::vector<int> order(n);
  for (int i = 0; i < n; ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return left->keypoints[a].v < left->keypoints[b].v;
  });
  for (int i : order) {
    Keypoint& kl = left->keypoints[i];
    kl.depth = 0.f;
    const int row = int(std::lround(kl.v));
    if (row < 0 || row >= H) continue;
    int best = std::numeric_limits<int>::max(), second = best, best_j = -1;
    for (int q = row_start[row]; q < row_start[row + 1]; ++q) {
      const int j = row_index[q];
      const Keypoint& kr = right.keypoints[j];
      if (std::abs(int(kr.octave) - int(kl.octave)) > 1) continue;
      const double d = kl.u - kr.u;
      if (d < min_d - 1.0 || d > max_d + 1.0) continue;
      const int dist = hammingDistance(left->descriptors[i], right.descriptors[j]);
      if (dist < best) {
        second = best;
        best = dist;
        best_j = j;
      } else if (dist < second) {
        second = dist;
      }
    }
    if (best_j < 0 || best > p.max_hamming) continue;
    if (second != std::numeric_limits<int>::max() && best >= p.ratio * second) continue;

    const int o = kl.octave;
    const double s = left->scales[o];
    const cv::Point2d kl_level = left->toLevel(o, kl.u, kl.v);
    const int xl = int(std::lround(kl_level.x)), y = int(std::lround(kl_level.y));
    const Keypoint& kr = right.keypoints[best_j];
    const int xr0 = int(std::lround(right.toLevel(o, kr.u, kr.v).x));
    double xr = 0, cost = 0;
    if (!refineDisparitySad(left->pyramid[o], right.pyramid[o], xl, y, xr0, p.sad_half_window,
                            p.sad_search_radius, &xr, &cost, parabola))
      continue;
    // The level-o match measured from the integer pixel xl, carried to kl.u.
    double u_right = kl.u - (left->toBase(o, xl, y).x - right.toBase(o, xr, y).x);
    if (o > 0) {
      // Coarse-to-fine: the level-o estimate is refined again on level 0, where a
      // pixel is s times smaller, within the level-o uncertainty.
      // The level-0 patch is centred on the integer pixel nearest the keypoint,
      // so the disparity is measured from there and carried back to kl.u.
      double xr0_fine = 0, cost0 = 0;
      const int radius0 = std::max(2, int(std::ceil(s)));
      const int xl0 = int(std::lround(kl.u));
      const double d_coarse = kl.u - u_right;
      if (!refineDisparitySad(left->pyramid[0], right.pyramid[0], xl0, int(std::lround(kl.v)),
                              int(std::lround(xl0 - d_coarse)), p.sad_half_window, radius0,
                              &xr0_fine, &cost0, parabola))
        continue;
      u_right = kl.u - (xl0 - xr0_fine);
      cost = cost0;
    }
    const double d = kl.u - u_right;
    if (d < min_d || d > max_d) continue;
    out.u_right[i] = float(u_right);
    out.disparity[i] = float(d);
    costs[i] = cost;
  }

  // Reject matches whose patch correlation is much worse than the typical one.
  std::vector<double> valid;
  for (double c : costs)
    if (c >= 0) valid.push_back(c);
  if (!valid.empty()) {
    std::nth_element(valid.begin(), valid.begin() + valid.size() / 2, valid.end());
    const double limit = p.sad_outlier_factor * std::max(valid[valid.size() / 2], 1.0);
    for (int i = 0; i < n; ++i) {
      if (costs[i] < 0) continue;
      if (costs[i] > limit) {
        out.u_right[i] = -1.f;
        out.disparity[i] = 0.f;
        continue;
      }
      left->keypoints[i].depth = float(K.fx * baseline / out.disparity[i]);
      ++out.matched;
    }
  }
  return out;
}

}  // namespace hermes
