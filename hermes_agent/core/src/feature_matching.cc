#include "hermes/agent/feature_matching.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace hermes {

KeypointGrid::KeypointGrid(const std::vector<Keypoint>& keypoints, int width, int height,
                           int cell_px)
    : keypoints_(&keypoints), cell_(std::max(1, cell_px)) {
  cols_ = std::max(1, (width + cell_ - 1) / cell_);
  rows_ = std::max(1, (height + cell_ - 1) / cell_);
  cells_.resize(size_t(cols_) * rows_);
  for (int i = 0; i < int(keypoints.size()); ++i) {
    const int cx = std::clamp(int(keypoints[i].u / cell_), 0, cols_ - 1);
    const int cy = std::clamp(int(keypoints[i].v / cell_), 0, rows_ - 1);
    cells_[size_t(cy) * cols_ + cx].push_back(i);
  }
}

std::vector<int> KeypointGrid::query(double u, double v, double radius, int min_octave,
                                     int max_octave) const {
  std::vector<int> out;
  if (!(radius >= 0) || !std::isfinite(u) || !std::isfinite(v)) return out;
  const int x0 = std::max(0, int(std::floor((u - radius) / cell_)));
  const int x1 = std::min(cols_ - 1, int(std::floor((u + radius) / cell_)));
  const int y0 = std::max(0, int(std::floor((v - radius) / cell_)));
  const int y1 = std::min(rows_ - 1, int(std::floor((v + radius) / cell_)));
  const double r2 = radius * radius;
  for (int cy = y0; cy <= y1; ++cy)
    for (int cx = x0; cx <= x1; ++cx)
      for (int i : cells_[size_t(cy) * cols_ + cx]) {
        const Keypoint& k = (*keypoints_)[i];
        if (min_octave >= 0 && k.octave < min_octave) continue;
        if (max_octave >= 0 && k.octave > max_octave) continue;
        const double du = k.u - u, dv = k.v - v;
        if (du * du + dv * dv <= r2) out.push_back(i);
      }
  return out;
}

Status ProjectionMatchParams::read(const Config& c, const std::string& p) {
  for (auto [key, ptr] : {std::pair<const char*, double*>{"radius_px", &radius_px},
                          {"ratio", &ratio},
                          {"min_depth", &min_depth}}) {
    Status s = c.get(p + "." + key, ptr);
    if (!s) return s;
  }
  for (auto [key, ptr] : {std::pair<const char*, int*>{"max_hamming", &max_hamming},
                          {"orientation_bins", &orientation_bins}}) {
    Status s = c.get(p + "." + key, ptr);
    if (!s) return s;
  }
  Status s = c.get(p + ".check_orientation", &check_orientation);
  if (!s) return s;
  return validate();
}

void ProjectionMatchParams::write(ConfigWriter* w, const std::string& p) const {
  w->set(p + ".radius_px", radius_px);
  w->set(p + ".max_hamming", max_hamming);
  w->set(p + ".ratio", ratio);
  w->set(p + ".check_orientation", check_orientation);
  w->set(p + ".orientation_bins", orientation_bins);
  w->set(p + ".min_depth", min_depth);
}

Status ProjectionMatchParams::validate() const {
  if (!(radius_px > 0)) return Error{"matching.radius_px must be > 0"};
  if (max_hamming < 0 || max_hamming > 256) return Error{"matching.max_hamming must be in [0, 256]"};
  if (!(ratio > 0 && ratio <= 1)) return Error{"matching.ratio must be in (0, 1]"};
  if (orientation_bins < 4 || orientation_bins > 360)
    return Error{"matching.orientation_bins must be in [4, 360]"};
  if (!(min_depth > 0)) return Error{"matching.min_depth must be > 0"};
  return Status::Ok();
}

namespace {

/// Matching core: landmark i against the keypoints `candidates(i)` returns
/// (empty = skip), ratio test, one landmark per keypoint, orientation check.
template <typename Candidates>
std::vector<int> matchLandmarks(const std::vector<LandmarkView>& landmarks, const FeatureSet& frame,
                                const ProjectionMatchParams& p, Candidates candidates) {
  HERMES_CHECK(frame.descriptors.size() == frame.keypoints.size(),
               "landmark matching: one descriptor per keypoint");
  const int n = int(landmarks.size());
  std::vector<int> match(n, -1), dist(n, 0);
  std::vector<int> owner(frame.size(), -1);  // keypoint -> landmark
  for (int i = 0; i < n; ++i) {
    int best = std::numeric_limits<int>::max(), second = best, best_j = -1;
    for (int j : candidates(i)) {
      const int d = hammingDistance(landmarks[i].descriptor, frame.descriptors[j]);
      if (d < best) {
        second = best;
        best = d;
        best_j = j;
      } else if (d < second) {
        second = d;
      }
    }
    if (best_j < 0 || best > p.max_hamming) continue;
    if (second != std::numeric_limits<int>::max() && best >= p.ratio * second) continue;
    const int prev = owner[best_j];
    if (prev >= 0) {
      if (dist[prev] <= best) continue;
      match[prev] = -1;
    }
    owner[best_j] = i;
    match[i] = best_j;
    dist[i] = best;
  }

  if (p.check_orientation && frame.angles.size() == frame.keypoints.size()) {
    // Histogram of angle changes; keep the dominant bin and its two neighbours.
    const int B = p.orientation_bins;
    std::vector<int> bin_of(n, -1), hist(B, 0);
    for (int i = 0; i < n; ++i) {
      if (match[i] < 0 || landmarks[i].angle < 0) continue;
      double rot = frame.angles[match[i]] - landmarks[i].angle;
      rot = std::fmod(rot + 720.0, 360.0);
      bin_of[i] = std::min(B - 1, int(rot * B / 360.0));
      hist[bin_of[i]]++;
    }
    const int top = int(std::max_element(hist.begin(), hist.end()) - hist.begin());
    if (hist[top] > 0) {
      for (int i = 0; i < n; ++i) {
        if (bin_of[i] < 0) continue;
        const int off = std::min((bin_of[i] - top + B) % B, (top - bin_of[i] + B) % B);
        if (off > 1) match[i] = -1;
      }
    }
  }
  return match;
}

}  // namespace

std::vector<int> matchByProjection(const std::vector<LandmarkView>& landmarks,
                                   const SE3& T_C_W, const PinholeIntrinsics& K,
                                   const FeatureSet& frame, const KeypointGrid& grid,
                                   const ProjectionMatchParams& p) {
  return matchLandmarks(landmarks, frame, p, [&](int i) -> std::vector<int> {
    const Vec3 p_C = T_C_W * landmarks[i].p_W;
    if (p_C.z() < p.min_depth) return {};
    const Vec2 uv = K.project(p_C);
    if (!K.inImage(uv)) return {};
    return grid.query(uv.x(), uv.y(), p.radius_px);
  });
}

std::vector<int> matchByDescriptor(const std::vector<LandmarkView>& landmarks,
                                   const FeatureSet& frame, const ProjectionMatchParams& p) {
  std::vector<int> all(frame.size());
  for (std::size_t j = 0; j < all.size(); ++j) all[j] = int(j);
  return matchLandmarks(landmarks, frame, p, [&](int) -> const std::vector<int>& { return all; });
}

}  // namespace hermes
