#include "room_sequence.h"

#include <cmath>

#include "plane_scene.h"

namespace hermes::test {

PinholeIntrinsics roomK() {
  PinholeIntrinsics K;
  K.fx = K.fy = 436.0;
  K.cx = 375.5;
  K.cy = 239.5;
  K.width = 752;
  K.height = 480;
  return K;
}

SE3 roomGroundTruth(int k) {
  const double t = k / 20.0;
  const Vec3 p(0.4 * std::sin(0.8 * t), 0.05 * std::sin(1.3 * t), 0.25 * t);
  const Vec3 w(0.03 * std::sin(1.0 * t), 0.1 * std::sin(0.6 * t), 0.0);
  return SE3(expSO3(w), p);
}

cv::Mat addSensorNoise(const cv::Mat& img, int seed) {
  cv::Mat n(img.size(), CV_16S);
  cv::RNG rng(seed);
  rng.fill(n, cv::RNG::NORMAL, 0, 2.0);
  cv::Mat out;
  cv::add(img, n, out, cv::noArray(), CV_8U);
  return out;
}

RoomRunStats runRoomSequence(Tracker* tracker, bool stereo, int frames,
                             const std::function<void(double, const TrackResult&)>& after) {
  RoomRunStats st;
  auto scene = roomCornerScene();
  if (scene.empty()) return st;
  const PinholeIntrinsics K = roomK();
  const SE3 T_C_R(Quat::Identity(), Vec3(0.11, 0, 0));
  const SE3 T_C0_W = roomGroundTruth(0).inverse();
  double sq = 0, ba_sum = 0;
  int ba_n = 0;
  for (int k = 0; k < frames; ++k) {
    const SE3 T_W_C = roomGroundTruth(k);
    CameraFrame f;
    f.stamp = k / 20.0;
    cv::Mat depth;
    f.left = addSensorNoise(renderPlanes(scene, K, T_W_C, &depth), 2 * k);
    if (stereo)
      f.right = addSensorNoise(renderPlanes(scene, K, T_W_C * T_C_R), 2 * k + 1);
    else
      f.depth = depth;
    auto r = tracker->feed(f);
    if (!r.ok()) return st;
    ++st.frames;
    if (r->new_keyframe && r->mapping.ba_ms > 0) {
      ba_sum += r->mapping.ba_ms;
      ++ba_n;
      st.max_ba_ms = std::max(st.max_ba_ms, r->mapping.ba_ms);
    }
    if (after) after(f.stamp, *r);
    if (r->status != TrackingStatus::kOk) {
      ++st.lost;
      continue;
    }
    const double e = (r->T_W_C.translation() - (T_C0_W * T_W_C).translation()).norm();
    sq += e * e;
  }
  st.rmse = std::sqrt(sq / std::max(1, st.frames - st.lost));
  st.mean_ba_ms = ba_n ? ba_sum / ba_n : 0;
  st.keyframes = int(tracker->keyframes().size());
  return st;
}

}  // namespace hermes::test
