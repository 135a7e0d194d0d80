#include "hermes/distill/scores.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <unordered_map>

namespace hermes {
namespace distill {

std::vector<SE3> predictFuturePoses(const MotionHint& hint, int count, double horizon_s) {
  std::vector<SE3> out;
  if (!hint.valid || count <= 0 || !(hint.dt_s > 0)) return out;
  const Vec6 twist = hint.T_Cprev_Ccurr.log() / hint.dt_s;  // body-frame velocity
  for (int i = 1; i <= count; ++i) {
    const double tau = horizon_s * static_cast<double>(i) / count;
    out.push_back(hint.T_A_C * SE3::exp(twist * tau));
  }
  return out;
}

Eigen::Matrix<double, 3, 6> bearingJacobian(const Vec3& p, const Vec3& P_C) {
  Eigen::Matrix<double, 3, 6> W;
  const Mat3 px = hat(p);
  W.leftCols<3>() = px * hat(P_C);
  W.rightCols<3>() = -px;
  return W;
}

double logDetSpd(const Mat6& M) {
  Eigen::LLT<Mat6> llt(M);
  if (llt.info() != Eigen::Success) return -std::numeric_limits<double>::infinity();
  const auto& L = llt.matrixL();
  double s = 0;
  for (int i = 0; i < 6; ++i) s += std::log(L(i, i));
  return 2.0 * s;
}

double informationGain(const Mat6& Lambda, double delta) {
  return logDetSpd(delta * Mat6::Identity() + Lambda) - 6.0 * std::log(delta);
}

double logDetObjective(const std::vector<Mat6>& lambdas, const std::vector<int>& subset,
                       double delta) {
  Mat6 M = delta * Mat6::Identity();
  for (int i : subset) M += lambdas[static_cast<std::size_t>(i)];
  return logDetSpd(M);
}

ScoreWeights scoreWeights(const Submap& window, int loop_closures, const DistillParams& params) {
  double a = params.alpha, b = params.beta;
  if (params.adaptive_weights) {
    double rot = 0;
    int pairs = 0;
    for (std::size_t i = 1; i < window.keyframes.size(); ++i) {
      rot += angularDistance(window.keyframes[i - 1].T_A_C, window.keyframes[i].T_A_C);
      ++pairs;
    }
    const double mean_rot = pairs > 0 ? rot / pairs : 0.0;
    a = params.alpha * (1.0 + params.alpha_per_loop * std::min(std::max(loop_closures, 0), 10));
    b = params.beta * (1.0 + params.beta_per_rad * mean_rot);
  }
  ScoreWeights w;
  w.alpha = a / (a + b);
  w.beta = b / (a + b);
  return w;
}

std::vector<double> normalise01(const std::vector<double>& v) {
  std::vector<double> out(v.size(), 1.0);
  if (v.empty()) return out;
  const auto [lo, hi] = std::minmax_element(v.begin(), v.end());
  const double range = *hi - *lo;
  if (range <= 1e-12) return out;
  for (std::size_t i = 0; i < v.size(); ++i) out[i] = (v[i] - *lo) / range;
  return out;
}

LandmarkScores computeScores(const Submap& window, const MotionHint& hint, int loop_closures,
                             const DistillParams& params) {
  LandmarkScores s;
  const std::size_t n = window.landmarks.size();
  s.q_s.assign(n, 0.0);
  s.q_a.assign(n, 0.0);
  s.lambda.assign(n, Mat6::Zero());
  std::unordered_map<KeyframeId, std::size_t> kf_index;
  std::vector<SE3> T_C_A(window.keyframes.size());
  for (std::size_t k = 0; k < window.keyframes.size(); ++k) {
    kf_index[window.keyframes[k].id] = k;
    T_C_A[k] = window.keyframes[k].T_A_C.inverse();
  }
  const std::vector<SE3> future =
      predictFuturePoses(hint, params.future_poses, params.future_horizon_s);
  std::vector<SE3> T_Cf_A;
  for (const SE3& T : future) T_Cf_A.push_back(T.inverse());
  const PinholeIntrinsics* fcam =
      hint.camera_id < window.cameras.size() ? &window.cameras[hint.camera_id] : nullptr;

  for (std::size_t i = 0; i < n; ++i) {
    const Landmark& lm = window.landmarks[i];
    Mat6 L = Mat6::Zero();
    for (const Observation& ob : lm.observations) {
      auto it = kf_index.find(ob.keyframe);
      if (it == kf_index.end()) continue;
      const Keyframe& kf = window.keyframes[it->second];
      if (ob.keypoint >= kf.keypoints.size() || kf.camera_id >= window.cameras.size()) continue;
      const Keypoint& kp = kf.keypoints[ob.keypoint];
      const Vec3 p = window.cameras[kf.camera_id].bearing(Vec2(kp.u, kp.v));
      const auto W = bearingJacobian(p, T_C_A[it->second] * lm.p_A);
      L.noalias() += W.transpose() * W;
      s.q_s[i] += 1.0;
    }
    if (fcam != nullptr) {
      for (const SE3& T : T_Cf_A) {
        const Vec3 P_C = T * lm.p_A;
        if (P_C.z() <= 1e-6) continue;
        if (!fcam->inImage(fcam->project(P_C))) continue;
        const auto W = bearingJacobian(P_C.normalized(), P_C);
        L.noalias() += W.transpose() * W;
      }
    }
    s.lambda[i] = L;
    s.q_a[i] = informationGain(L, params.delta);
  }
  s.weights = scoreWeights(window, loop_closures, params);
  const std::vector<double> qs = normalise01(s.q_s), qa = normalise01(s.q_a);
  s.value.resize(n);
  for (std::size_t i = 0; i < n; ++i)
    s.value[i] = s.weights.alpha * qs[i] + s.weights.beta * qa[i];
  return s;
}

}  // namespace distill
}  // namespace hermes
