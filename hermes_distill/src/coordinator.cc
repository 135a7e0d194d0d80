#include "hermes/distill/coordinator.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include <Eigen/Dense>

namespace hermes {
namespace distill {

double budgetBytes(const DistillParams& params, const CoordinatorInput& in) {
  const double period = in.period_s > 0 ? in.period_s : params.window_s;
  return params.eta * std::max(0.0, in.bandwidth_Bps) * period - in.backlog_bytes;
}

ByteModel::ByteModel(const DistillParams& p)
    : prior_{p.bytes_c0, p.bytes_kf, p.bytes_obs, p.bytes_lm}, c_(prior_) {}

double ByteModel::predict(double n_kf, double obs, double n_lm) const {
  return c_[0] + c_[1] * n_kf + c_[2] * obs + c_[3] * n_lm;
}

void ByteModel::addSample(double n_kf, double obs, double n_lm, double bytes) {
  samples_.push_back({n_kf, obs, n_lm, 1.0, bytes});
  while (samples_.size() > 64) samples_.pop_front();
  refit();
}

void ByteModel::refit() {
  // Unknowns ordered like c_: [c0, c_kf, c_obs, c_lm]. Ridge towards the prior,
  // scaled per feature so that the regulariser is unit-free.
  Eigen::Matrix4d A = Eigen::Matrix4d::Zero();
  Eigen::Vector4d b = Eigen::Vector4d::Zero();
  Eigen::Vector4d scale = Eigen::Vector4d::Zero();
  for (const auto& s : samples_) {
    const Eigen::Vector4d x(1.0, s[0], s[1], s[2]);
    A += x * x.transpose();
    b += x * s[4];
    scale += x.cwiseAbs2();
  }
  // The prior weighs like one average sample per coefficient.
  const double n = static_cast<double>(std::max<std::size_t>(1, samples_.size()));
  for (int k = 0; k < 4; ++k) {
    const double w = std::max(scale[k] / n, 1.0);
    A(k, k) += w;
    b[k] += w * prior_[static_cast<std::size_t>(k)];
  }
  const Eigen::Vector4d c = A.ldlt().solve(b);
  if (!c.allFinite()) return;
  c_[0] = std::max(0.0, c[0]);
  c_[1] = std::max(0.0, c[1]);
  c_[2] = std::max(1.0, c[2]);
  c_[3] = std::max(1.0, c[3]);
}

int keyframeFloor(const Submap& w, const DistillParams& params) {
  const int n = static_cast<int>(w.keyframes.size());
  if (n == 0) return 0;
  double span = params.window_s;
  if (n >= 2) span = std::max(w.keyframes.back().stamp - w.keyframes.front().stamp, 1e-3);
  const int floor = std::max(2, static_cast<int>(std::ceil(params.min_keyframe_rate_hz * span)));
  return std::min(n, floor);
}

void predictKept(const Submap& w, int n_kf, int k, double* landmarks, double* observations) {
  const double n = static_cast<double>(std::max<std::size_t>(1, w.keyframes.size()));
  const double total_obs = static_cast<double>(w.observationCount());
  const double total_lm = static_cast<double>(std::max<std::size_t>(1, w.landmarks.size()));
  const double mean_track = total_obs / total_lm;          // over the whole window
  const double mean_per_kf = total_obs / n;                // n_j
  const double track = std::max(1.0, mean_track * n_kf / n);  // after trimming
  const double k_eff = std::min<double>(k, mean_per_kf);
  const double lm = std::min(total_lm, n_kf * k_eff / track * 1.3);  // support > K typically
  *landmarks = lm;
  *observations = std::min(lm * track, n_kf * mean_per_kf);
}

void KeptModel::predict(const Submap& w, int n_kf, int k, double* landmarks,
                        double* observations) const {
  predictKept(w, n_kf, k, landmarks, observations);
  *landmarks *= landmarkRatio();
  *observations *= observationRatio();
}

void KeptModel::addSample(const Submap& w, int n_kf, int k, double landmarks, double observations,
                          bool budget_bound) {
  double lm0 = 0, obs0 = 0;
  predictKept(w, n_kf, k, &lm0, &obs0);
  if (!(lm0 > 0) || !(obs0 > 0) || !(landmarks > 0) || !(observations > 0)) return;
  // Running mean of the log-ratios, the prior (log 1 = 0) counting as half a
  // sample; from the 6th sample on a constant gain, so the model follows drift.
  const double gain = 1.0 / (0.5 + static_cast<double>(std::min<std::size_t>(samples_ + 1, 6)));
  const double lo = std::log(kMinRatio), hi = std::log(kMaxRatio);
  const double seen[2] = {std::log(landmarks / lm0), std::log(observations / obs0)};
  for (int i = 0; i < 2; ++i) {
    double x = std::clamp(seen[i], lo, hi);
    if (budget_bound) x = std::max(x, log_ratio_[static_cast<std::size_t>(i)]);  // censored
    double& r = log_ratio_[static_cast<std::size_t>(i)];
    r = std::clamp(r + gain * (x - r), lo, hi);
  }
  ++samples_;
}

CoordinatorPlan chooseK(const Submap& trimmed, double budget, const ByteModel& model,
                        const KeptModel& kept, const DistillParams& params) {
  CoordinatorPlan plan;
  plan.n_kf = static_cast<int>(trimmed.keyframes.size());
  auto bytes = [&](int k) {
    double lm, obs;
    kept.predict(trimmed, plan.n_kf, k, &lm, &obs);
    return model.predict(plan.n_kf, obs, lm);
  };
  plan.k = params.k_min;
  for (double limit : {params.plan_fill * budget, budget}) {
    int k = params.k_max;
    while (k > params.k_min && bytes(k) > limit) --k;
    if (bytes(k) <= limit) {
      plan.k = k;
      break;
    }
  }
  plan.predicted_bytes = bytes(plan.k);
  return plan;
}

CoordinatorPlan planDistillation(const Submap& w, double budget, const ByteModel& model,
                                 const KeptModel& kept, const DistillParams& params,
                                 int surplus_max_keyframes) {
  CoordinatorPlan plan;
  const int n = static_cast<int>(w.keyframes.size());
  const int n_min = keyframeFloor(w, params);
  const int n_max = std::max(n_min, std::min(n, params.max_keyframes));
  const int k_pref = std::clamp(params.k_pref, params.k_min, params.k_max);
  const double target = params.plan_fill * budget;
  auto bytes = [&](int nk, int k) {
    double lm, obs;
    kept.predict(w, nk, k, &lm, &obs);
    return model.predict(nk, obs, lm);
  };
  auto largestK = [&](int nk, int lo, int hi, double limit) {  // largest fitting K in [lo, hi], or -1
    for (int k = hi; k >= lo; --k)
      if (bytes(nk, k) <= limit) return k;
    return -1;
  };
  // 0) A fast window's keyframes beyond n_max, only where each still carries k_max.
  for (int nk = std::min(n, surplus_max_keyframes); nk > n_max; --nk) {
    const double predicted = bytes(nk, params.k_max);
    if (predicted > target) continue;
    plan.n_kf = nk;
    plan.k = params.k_max;
    plan.predicted_bytes = predicted;
    return plan;
  }
  // 1) The most keyframes that still carry the preferred K; then the largest K.
  for (int nk = n_max; nk >= n_min; --nk) {
    if (bytes(nk, k_pref) > target) continue;
    plan.n_kf = nk;
    plan.k = largestK(nk, k_pref, params.k_max, target);
    plan.predicted_bytes = bytes(nk, plan.k);
    return plan;
  }
  // 2) At the keyframe floor, the largest K down to k_min: within the target if
  // possible, else within the budget itself.
  for (double limit : {target, budget}) {
    const int k = largestK(n_min, params.k_min, k_pref - 1, limit);
    if (k > 0 && n_min > 0) {
      plan.n_kf = n_min;
      plan.k = k;
      plan.predicted_bytes = bytes(n_min, k);
      return plan;
    }
  }
  plan.defer = true;
  std::ostringstream why;
  why << "budget " << budget << " B is below the floor (" << n_min << " keyframes, K = "
      << params.k_min << ": " << bytes(std::max(n_min, 1), params.k_min) << " B predicted)";
  plan.reason = why.str();
  return plan;
}

}  // namespace distill
}  // namespace hermes
