#include "hermes/core/evaluation.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace hermes {
namespace eval {

namespace {
constexpr double kRadToDeg = 180.0 / M_PI;
}

Status EvalParams::read(const Config& config, const std::string& section) {
  const std::string p = section.empty() ? "" : section + ".";
  std::string align_name = toString(align);
  Status s = config.getChoice(p + "align", {"none", "first", "se3", "sim3"}, &align_name);
  if (!s) return s;
  align = *parseAlignMode(align_name);
  if (!(s = config.get(p + "max_dt", &max_dt))) return s;
  if (!(s = config.get(p + "rpe_delta_s", &rpe_delta_s))) return s;
  if (!(s = config.get(p + "rpe_delta_frames", &rpe_delta_frames))) return s;
  if (!(s = config.get(p + "rpe_tolerance", &rpe_tolerance))) return s;
  return validate();
}

Status EvalParams::validate() const {
  if (!(max_dt >= 0) || !std::isfinite(max_dt))
    return Error{"eval.max_dt must be a finite value >= 0, got " + std::to_string(max_dt)};
  if (!(rpe_delta_s > 0) || !std::isfinite(rpe_delta_s))
    return Error{"eval.rpe_delta_s must be > 0, got " + std::to_string(rpe_delta_s)};
  if (rpe_delta_frames < 0)
    return Error{"eval.rpe_delta_frames must be >= 0, got " + std::to_string(rpe_delta_frames)};
  if (!(rpe_tolerance >= 0) || !std::isfinite(rpe_tolerance))
    return Error{"eval.rpe_tolerance must be a finite value >= 0, got " + std::to_string(rpe_tolerance)};
  return Status::Ok();
}

Expected<Association> associate(const Trajectory& gt, const Trajectory& est, double max_dt) {
  if (gt.empty()) return Error{"ground truth holds no poses"};
  for (size_t i = 1; i < gt.size(); ++i)
    if (!(gt[i].t > gt[i - 1].t))
      return Error{"ground truth timestamps must increase (pose " + std::to_string(i) + ", t=" +
                   std::to_string(gt[i].t) + ")"};
  for (size_t i = 1; i < est.size(); ++i)
    if (!(est[i].t > est[i - 1].t))
      return Error{"estimate timestamps must increase (pose " + std::to_string(i) + ", t=" +
                   std::to_string(est[i].t) + ")"};
  Association a;
  a.t.reserve(est.size());
  a.gt.reserve(est.size());
  a.est.reserve(est.size());
  for (const StampedPose& e : est) {
    const auto it = std::lower_bound(gt.begin(), gt.end(), e.t,
                                     [](const StampedPose& p, double v) { return p.t < v; });
    double nearest = std::numeric_limits<double>::infinity();
    if (it != gt.end()) nearest = it->t - e.t;
    if (it != gt.begin()) nearest = std::min(nearest, e.t - (it - 1)->t);
    if (!std::isfinite(e.t) || !(nearest <= max_dt)) {
      ++a.unmatched;
      continue;
    }
    SE3 T_W_B;
    if (it == gt.end()) {
      T_W_B = gt.back().T_W_B;  // just after the span, within max_dt
    } else if (it == gt.begin()) {
      T_W_B = gt.front().T_W_B;  // just before (or at) the first sample
    } else if (!interpolatePose(gt, e.t, &T_W_B)) {
      ++a.unmatched;
      continue;
    }
    a.t.push_back(e.t);
    a.gt.push_back(T_W_B);
    a.est.push_back(e.T_W_B);
  }
  return a;
}

double relativeAngle(const Quat& a, const Quat& b) {
  const Quat q = a.conjugate() * b;
  return 2.0 * std::atan2(q.vec().norm(), std::abs(q.w()));
}

ErrorStats computeStats(std::vector<double> v) {
  ErrorStats s;
  s.count = v.size();
  if (v.empty()) return s;
  std::sort(v.begin(), v.end());
  double sum = 0, sum_sq = 0;
  for (double x : v) {
    sum += x;
    sum_sq += x * x;
  }
  const double n = double(v.size());
  s.mean = sum / n;
  s.rmse = std::sqrt(sum_sq / n);
  s.min = v.front();
  s.max = v.back();
  const size_t mid = v.size() / 2;
  s.median = v.size() % 2 ? v[mid] : 0.5 * (v[mid - 1] + v[mid]);
  double var = 0;
  for (double x : v) var += (x - s.mean) * (x - s.mean);
  s.std = std::sqrt(var / n);
  return s;
}

AteResult ateWithAlignment(const Association& assoc, const Alignment& alignment) {
  AteResult r;
  r.alignment = alignment;
  std::vector<double> rot;
  r.trans_errors_m.reserve(assoc.matched());
  rot.reserve(assoc.matched());
  for (size_t i = 0; i < assoc.matched(); ++i) {
    const SE3 aligned = alignment.applyToPose(assoc.est[i]);
    r.trans_errors_m.push_back((assoc.gt[i].translation() - aligned.translation()).norm());
    rot.push_back(kRadToDeg * relativeAngle(assoc.gt[i].quat(), aligned.quat()));
  }
  r.trans_m = computeStats(r.trans_errors_m);
  r.rot_deg = computeStats(std::move(rot));
  return r;
}

Expected<AteResult> computeAte(const Association& assoc, AlignMode mode) {
  Expected<Alignment> al = alignPoses(assoc.gt, assoc.est, mode);
  if (!al) return Error{al.error()};
  return ateWithAlignment(assoc, *al);
}

RpeResult computeRpe(const Association& assoc, const Alignment& alignment,
                     const EvalParams& params) {
  RpeResult r;
  r.by_frames = params.rpe_delta_frames > 0;
  r.delta = r.by_frames ? params.rpe_delta_frames : params.rpe_delta_s;
  const size_t n = assoc.matched();
  std::vector<SE3> est;
  est.reserve(n);
  for (const SE3& e : assoc.est) est.push_back(alignment.applyToPose(e));
  std::vector<double> trans, rot;
  for (size_t i = 0; i < n; ++i) {
    size_t j = 0;
    if (r.by_frames) {
      j = i + size_t(params.rpe_delta_frames);
      if (j >= n) break;
    } else {
      // Partner: the first matched pose at least delta later (1 ns slack for rounding),
      // dropped when it comes more than rpe_tolerance * delta late (a gap).
      const double target = assoc.t[i] + params.rpe_delta_s - 1e-9;
      const auto it = std::lower_bound(assoc.t.begin() + long(i) + 1, assoc.t.end(), target);
      if (it == assoc.t.end()) break;
      const size_t best = size_t(it - assoc.t.begin());
      const double dt = assoc.t[best] - assoc.t[i];
      if (dt - params.rpe_delta_s > params.rpe_tolerance * params.rpe_delta_s) continue;
      j = best;
    }
    const SE3 rel_gt = assoc.gt[i].inverse() * assoc.gt[j];
    const SE3 rel_est = est[i].inverse() * est[j];
    const SE3 err = rel_gt.inverse() * rel_est;
    trans.push_back(err.translation().norm());
    rot.push_back(kRadToDeg * relativeAngle(Quat::Identity(), err.quat()));
  }
  r.pairs = trans.size();
  r.trans_m = computeStats(std::move(trans));
  r.rot_deg = computeStats(std::move(rot));
  return r;
}

Expected<TrajectoryEval> evaluateTrajectory(const Trajectory& gt, const Trajectory& est,
                                            const EvalParams& params, const std::string& name) {
  if (Status s = params.validate(); !s) return Error{s.error()};
  TrajectoryEval ev;
  ev.name = name;
  ev.est_poses = est.size();
  Expected<Association> assoc = associate(gt, est, params.max_dt);
  if (!assoc) return Error{name + ": " + assoc.error()};
  ev.assoc = std::move(*assoc);
  if (ev.assoc.matched() == 0)
    return Error{name + ": no estimate pose has ground truth within max_dt=" +
                 std::to_string(params.max_dt) + " s (" + std::to_string(est.size()) +
                 " estimate poses; check that both use the same time base)"};
  Expected<AteResult> ate = computeAte(ev.assoc, params.align);
  if (!ate) return Error{name + ": " + ate.error()};
  ev.ate = std::move(*ate);
  ev.rpe = computeRpe(ev.assoc, ev.ate.alignment, params);
  return ev;
}

Expected<MultiAgentEval> evaluateAgents(const std::vector<AgentTrajectories>& agents,
                                        const EvalParams& params, bool allow_partial) {
  if (agents.empty()) return Error{"no agents to evaluate"};
  MultiAgentEval m;
  Association pooled;
  std::vector<size_t> offsets;
  for (const AgentTrajectories& a : agents) {
    Expected<TrajectoryEval> ev = evaluateTrajectory(a.gt, a.est, params, a.name);
    if (!ev) {
      if (!allow_partial) return Error{ev.error()};
      m.failed.push_back({a.name, ev.error()});
      continue;
    }
    offsets.push_back(pooled.matched());
    const Association& as = ev->assoc;
    pooled.t.insert(pooled.t.end(), as.t.begin(), as.t.end());
    pooled.gt.insert(pooled.gt.end(), as.gt.begin(), as.gt.end());
    pooled.est.insert(pooled.est.end(), as.est.begin(), as.est.end());
    pooled.unmatched += as.unmatched;
    m.agents.push_back(std::move(*ev));
  }
  if (m.agents.empty()) return Error{"no agent could be evaluated: " + m.failed.front().error};
  offsets.push_back(pooled.matched());
  m.matched = pooled.matched();
  m.unmatched = pooled.unmatched;
  Expected<AteResult> merged = computeAte(pooled, params.align);
  if (!merged) return Error{"merged trajectory: " + merged.error()};
  m.merged_ate = std::move(*merged);
  m.merged_alignment = m.merged_ate.alignment;
  for (size_t k = 0; k + 1 < offsets.size(); ++k)
    m.merged_per_agent_m.push_back(
        computeStats({m.merged_ate.trans_errors_m.begin() + long(offsets[k]),
                      m.merged_ate.trans_errors_m.begin() + long(offsets[k + 1])}));
  return m;
}

}  // namespace eval
}  // namespace hermes
