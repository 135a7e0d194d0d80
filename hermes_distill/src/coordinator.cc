#include "hermes/distill/coordinator.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include <Eigen/Dense>

namespace hermes {
namespace distill {

double budgetBytes(const DistillParams& params, const CoordinatorInput& in) {
  const double gain = in.probe ? 1.0 + params.probe_gain : 1.0;
  return params.eta * std::max(0.0, in.bandwidth_Bps) * params.window_s * gain - in.backlog_bytes;
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
  const double mu = 0.05;
  for (int k = 0; k < 4; ++k) {
    const double w = mu * std::max(scale[k], 1.0);
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

CoordinatorPlan planDistillation(const Submap& w, double budget, const ByteModel& model,
                                 const DistillParams& params) {
  CoordinatorPlan plan;
  const int n = static_cast<int>(w.keyframes.size());
  const int n_max = std::min(n, params.max_keyframes);
  const int n_min = keyframeFloor(w, params);
  const double mean_per_kf =
      n > 0 ? static_cast<double>(w.observationCount()) / n : 0.0;
  double best = -1;
  for (int nk = std::max(n_min, 1); nk <= std::max(n_max, n_min); ++nk) {
    for (int k = params.k_min; k <= params.k_max; ++k) {
      double lm, obs;
      predictKept(w, nk, k, &lm, &obs);
      const double bytes = model.predict(nk, obs, lm);
      if (bytes > budget) continue;
      const double utility = std::sqrt(static_cast<double>(nk)) * std::min<double>(k, mean_per_kf) + 1e-6 * k;
      if (utility > best) {
        best = utility;
        plan.n_kf = nk;
        plan.k = k;
        plan.predicted_bytes = bytes;
      }
    }
  }
  if (best < 0) {
    plan.defer = true;
    std::ostringstream why;
    why << "budget " << budget << " B is below the floor (" << n_min << " keyframes, K = "
        << params.k_min << ")";
    plan.reason = why.str();
  }
  return plan;
}

}  // namespace distill
}  // namespace hermes
