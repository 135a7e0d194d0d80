#include "hermes/distill/synthetic_window.h"

#include "hermes/core/odometry_noise.h"

#include <algorithm>
#include <cmath>

namespace hermes {
namespace distill {

SE3 eurocCam0TBC() {
  Mat4 T;
  T << 0.0148655429818, -0.999880929698, 0.00414029679422, -0.0216401454975,
      0.999557249008, 0.0149672133247, 0.025715529948, -0.064676986768,
      -0.0257744366974, 0.00375618835797, 0.999660727178, 0.00981073058949,
      0.0, 0.0, 0.0, 1.0;
  return SE3(T);
}

PinholeIntrinsics eurocCam0Intrinsics() {
  PinholeIntrinsics K;
  K.fx = 458.654;
  K.fy = 457.296;
  K.cx = 367.215;
  K.cy = 248.375;
  K.width = 752;
  K.height = 480;
  return K;
}

SyntheticScene::SyntheticScene(Trajectory trajectory, const SyntheticWindowParams& params,
                               SE3 T_B_C, PinholeIntrinsics camera)
    : traj_(std::move(trajectory)), params_(params), T_B_C_(T_B_C), cam_(camera) {
  if (traj_.empty()) return;
  Vec3 lo = traj_.front().T_W_B.translation(), hi = lo;
  for (const StampedPose& p : traj_) {
    lo = lo.cwiseMin(p.T_W_B.translation());
    hi = hi.cwiseMax(p.T_W_B.translation());
  }
  lo -= Vec3::Constant(params_.box_margin_m);
  hi += Vec3::Constant(params_.box_margin_m);
  const Vec3 size = hi - lo;
  // Faces: axis (0,1,2) × side (lo,hi); area-weighted sampling.
  std::mt19937_64 rng(params_.seed);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  const double areas[3] = {size.y() * size.z(), size.x() * size.z(), size.x() * size.y()};
  const double total = 2.0 * (areas[0] + areas[1] + areas[2]);
  const int count = static_cast<int>(params_.landmarks_per_m2 * total);
  points_.reserve(static_cast<std::size_t>(count));
  for (int i = 0; i < count; ++i) {
    double r = uni(rng) * total / 2.0;
    int axis = 0;
    while (axis < 2 && r > areas[axis]) r -= areas[axis++];
    Vec3 p(lo.x() + uni(rng) * size.x(), lo.y() + uni(rng) * size.y(), lo.z() + uni(rng) * size.z());
    p[axis] = uni(rng) < 0.5 ? lo[axis] : hi[axis];
    points_.push_back(p);
    Descriptor d;
    for (auto& b : d) b = static_cast<std::uint8_t>(rng() & 0xff);
    descriptors_.push_back(d);
  }
}

double SyntheticScene::duration() const {
  return traj_.empty() ? 0.0 : traj_.back().t - traj_.front().t;
}

Expected<SyntheticWindow> SyntheticScene::window(double t_start_s, std::uint64_t seq) const {
  if (traj_.empty()) return Error{"synthetic window: empty trajectory"};
  const double t0 = traj_.front().t + t_start_s;
  const double t1 = t0 + params_.duration_s;
  if (t_start_s < 0 || t1 > traj_.back().t)
    return Error{"synthetic window [" + std::to_string(t_start_s) + ", +" +
                 std::to_string(params_.duration_s) + "] s leaves the trajectory (" +
                 std::to_string(duration()) + " s)"};
  std::mt19937_64 rng(params_.seed * 1000003ULL + seq);
  std::normal_distribution<double> noise(0.0, 1.0);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  SyntheticWindow out;
  Submap& s = out.submap;
  s.header.agent = uuidFromSeed(params_.seed);
  s.header.seq = seq;
  s.header.t_start = t0;
  s.header.t_end = t1;
  s.cameras.push_back(cam_);
  std::vector<int> lm_slot(points_.size(), -1);  // scene point -> landmark index
  const int n_kf = static_cast<int>(std::floor(params_.duration_s / params_.keyframe_period_s + 1e-9)) + 1;
  for (int k = 0; k < n_kf; ++k) {
    const double t = std::min(t1, t0 + k * params_.keyframe_period_s);
    SE3 T_W_B;
    if (!interpolatePose(traj_, t, &T_W_B)) return Error{"synthetic window: no pose at t=" + std::to_string(t)};
    Keyframe kf;
    kf.id = seq * 1000 + static_cast<KeyframeId>(k) + 1;
    kf.stamp = t;
    kf.T_A_C = T_W_B * T_B_C_;
    const SE3 T_C_W = kf.T_A_C.inverse();
    std::vector<std::pair<double, std::size_t>> visible;  // (depth, point)
    for (std::size_t i = 0; i < points_.size(); ++i) {
      const Vec3 P = T_C_W * points_[i];
      if (P.z() < 0.2 || P.z() > params_.max_depth_m) continue;
      if (!cam_.inImage(cam_.project(P), 2.0)) continue;
      visible.emplace_back(P.z(), i);
    }
    std::sort(visible.begin(), visible.end());
    if (static_cast<int>(visible.size()) > params_.max_observations_per_kf)
      visible.resize(static_cast<std::size_t>(params_.max_observations_per_kf));
    for (const auto& [depth, i] : visible) {
      const Vec3 P = T_C_W * points_[i];
      Vec2 uv = cam_.project(P) + params_.pixel_noise * Vec2(noise(rng), noise(rng));
      uv.x() = std::clamp(uv.x(), 0.0, cam_.width - 1.0);
      uv.y() = std::clamp(uv.y(), 0.0, cam_.height - 1.0);
      if (lm_slot[i] < 0) {
        lm_slot[i] = static_cast<int>(s.landmarks.size());
        Landmark lm;
        lm.id = static_cast<LandmarkId>(i) + 1;
        lm.p_A = points_[i] + params_.landmark_noise_m * Vec3(noise(rng), noise(rng), noise(rng));
        lm.descriptor = descriptors_[i];
        s.landmarks.push_back(lm);
      }
      Descriptor d = descriptors_[i];
      for (int f = 0; f < 3; ++f) d[rng() % 32] ^= static_cast<std::uint8_t>(1u << (rng() % 8));
      s.landmarks[static_cast<std::size_t>(lm_slot[i])].observations.push_back(
          {kf.id, static_cast<std::uint32_t>(kf.keypoints.size())});
      kf.keypoints.push_back({static_cast<float>(uv.x()), static_cast<float>(uv.y()),
                              static_cast<std::uint8_t>(rng() % 4), static_cast<float>(depth)});
      kf.descriptors.push_back(d);
      kf.keypoint_landmark.push_back(static_cast<LandmarkId>(i) + 1);
    }
    const int extra = static_cast<int>(params_.unlinked_fraction * visible.size());
    for (int e = 0; e < extra; ++e) {
      Descriptor d;
      for (auto& b : d) b = static_cast<std::uint8_t>(rng() & 0xff);
      kf.keypoints.push_back({static_cast<float>(uni(rng) * (cam_.width - 1)),
                              static_cast<float>(uni(rng) * (cam_.height - 1)),
                              static_cast<std::uint8_t>(rng() % 4), 0.0f});
      kf.descriptors.push_back(d);
      kf.keypoint_landmark.push_back(kInvalidId);
    }
    s.keyframes.push_back(std::move(kf));
  }
  // Odometry edges as the agent's window has them (the default noise model).
  for (std::size_t k = 1; k < s.keyframes.size(); ++k) {
    OdometryEdge e;
    e.from = s.keyframes[k - 1].id;
    e.to = s.keyframes[k].id;
    e.T_from_to = s.keyframes[k - 1].T_A_C.inverse() * s.keyframes[k].T_A_C;
    e.information = odometryInformation(e.T_from_to, -1, false, OdometryNoiseParams());
    s.odometry.push_back(e);
  }
  // Motion hint: the camera's last VO step (20 Hz) at the end of the window.
  SE3 T_W_B1, T_W_B0;
  const double dt = 0.05;
  if (interpolatePose(traj_, t1, &T_W_B1) && interpolatePose(traj_, t1 - dt, &T_W_B0)) {
    out.hint.valid = true;
    out.hint.T_A_C = T_W_B1 * T_B_C_;
    out.hint.T_Cprev_Ccurr = (T_W_B0 * T_B_C_).inverse() * out.hint.T_A_C;
    out.hint.dt_s = dt;
  }
  return out;
}

std::size_t referenceEncodedSize(const Submap& s) {
  std::size_t bytes = 64 + 40 * s.cameras.size();
  for (const Keyframe& kf : s.keyframes) bytes += 8 + 8 + 56 + 4 + 4 + kf.keypoints.size() * (13 + 32 + 8);
  bytes += s.odometry.size() * (16 + 56 + 168);
  for (const Landmark& lm : s.landmarks) bytes += 8 + 24 + 32 + 4 + 12 * lm.observations.size();
  return bytes;
}

Expected<SyntheticScene> makeSceneFromTum(const std::string& path,
                                          const SyntheticWindowParams& params) {
  auto traj = readTumTrajectory(path);
  if (!traj) return Error{traj.error()};
  if (traj->size() < 2) return Error{"trajectory " + path + " has fewer than 2 poses"};
  return SyntheticScene(std::move(traj.value()), params);
}

}  // namespace distill
}  // namespace hermes
