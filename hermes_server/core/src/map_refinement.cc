#include "hermes/server/map_refinement.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <memory>
#include <set>

#include <ceres/ceres.h>

#include "hermes/server/pose_graph.h"

namespace hermes {
namespace server {
namespace {

using Clock = std::chrono::steady_clock;

struct PoseBlock {
  double q[4];  // x, y, z, w (Eigen's storage order)
  double t[3];
  bool free = false;
  SE3 before;
  const StoredKeyframe* kf = nullptr;
};

struct PointBlock {
  double p[3];
  TrajectoryId traj;
  LandmarkId id = kInvalidId;
};

/// One observation: keypoint `kp` of keyframe `kf` sees point `point`.
struct Obs {
  KeyframeKey kf;
  std::uint32_t kp = 0;
  std::pair<TrajectoryId, LandmarkId> point;
  bool tie = false;
};

using PointKey = std::pair<TrajectoryId, LandmarkId>;

KeyframeKey keyIn(const TrajectoryId& t, KeyframeId id) { return KeyframeKey{t.first, t.second, id}; }
TrajectoryId trajOf(const KeyframeKey& k) { return {k.agent, k.session}; }

/// World position of a stored landmark (nullopt without an anchor).
bool landmarkWorld(const GlobalMap& map, const TrajectoryId& tid, LandmarkId id, Vec3* p_W) {
  const TrajectoryMap* t = map.trajectory(tid.first, tid.second);
  if (!t || !t->anchored) return false;
  auto l = t->landmarks.find(id);
  if (l == t->landmarks.end() || l->second.anchor == kInvalidId) return false;
  auto k = t->keyframes.find(l->second.anchor);
  if (k == t->keyframes.end()) return false;
  *p_W = k->second.T_W_C * l->second.p_anchor;
  return true;
}

/// The landmark keypoint `kp` of keyframe `key` belongs to (kInvalidId if none).
LandmarkId landmarkOf(const GlobalMap& map, const KeyframeKey& key, std::uint32_t kp) {
  const StoredKeyframe* k = map.keyframe(key);
  if (!k || kp >= k->keyframe.keypoint_landmark.size()) return kInvalidId;
  return k->keyframe.keypoint_landmark[kp];
}

std::unique_ptr<ceres::LossFunction> makeLoss(const MapRefinementParams& p) {
  if (p.loss == "huber") return std::make_unique<ceres::HuberLoss>(p.loss_scale);
  if (p.loss == "cauchy") return std::make_unique<ceres::CauchyLoss>(p.loss_scale);
  return nullptr;
}

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

double rms(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x * x;
  return v.empty() ? 0 : std::sqrt(s / static_cast<double>(v.size()));
}

}  // namespace

Status MapRefinementParams::read(const Config& config, const std::string& prefix) {
  const std::string p = prefix + ".";
  for (Status s : {config.get(p + "enabled", &enabled), config.get(p + "ties_per_loop", &ties_per_loop),
                   config.get(p + "neighbours", &neighbours), config.get(p + "max_loops", &max_loops),
                   config.get(p + "max_free_keyframes", &max_free_keyframes),
                   config.get(p + "max_fixed_keyframes", &max_fixed_keyframes),
                   config.get(p + "min_keyframe_residuals", &min_keyframe_residuals),
                   config.get(p + "pixel_sigma_px", &pixel_sigma_px),
                   config.get(p + "octave_scale", &octave_scale),
                   config.get(p + "depth_focal_baseline_px_m", &depth_focal_baseline_px_m),
                   config.getChoice(p + "loss", {"none", "huber", "cauchy"}, &loss),
                   config.get(p + "loss_scale", &loss_scale),
                   config.get(p + "max_iterations", &max_iterations),
                   config.get(p + "max_time_s", &max_time_s),
                   config.get(p + "max_pose_change_m", &max_pose_change_m),
                   config.get(p + "keep_in_pose_graph", &keep_in_pose_graph),
                   config.get(p + "odometry_weight", &odometry_weight)})
    if (!s) return s;
  if (Status s = validate(); !s) return Error{prefix + ": " + s.error()};
  return Status::Ok();
}

void MapRefinementParams::write(ConfigWriter* w, const std::string& prefix) const {
  const std::string p = prefix + ".";
  w->set(p + "enabled", enabled);
  w->set(p + "ties_per_loop", ties_per_loop);
  w->set(p + "neighbours", neighbours);
  w->set(p + "max_loops", max_loops);
  w->set(p + "max_free_keyframes", max_free_keyframes);
  w->set(p + "max_fixed_keyframes", max_fixed_keyframes);
  w->set(p + "min_keyframe_residuals", min_keyframe_residuals);
  w->set(p + "pixel_sigma_px", pixel_sigma_px);
  w->set(p + "octave_scale", octave_scale);
  w->set(p + "depth_focal_baseline_px_m", depth_focal_baseline_px_m);
  w->set(p + "loss", loss);
  w->set(p + "loss_scale", loss_scale);
  w->set(p + "max_iterations", max_iterations);
  w->set(p + "max_time_s", max_time_s);
  w->set(p + "max_pose_change_m", max_pose_change_m);
  w->set(p + "keep_in_pose_graph", keep_in_pose_graph);
  w->set(p + "odometry_weight", odometry_weight);
}

Status MapRefinementParams::validate() const {
  if (ties_per_loop < 0) return Error{"ties_per_loop must be >= 0"};
  if (neighbours < 0) return Error{"neighbours must be >= 0"};
  if (max_loops < 1) return Error{"max_loops must be >= 1"};
  if (max_free_keyframes < 1) return Error{"max_free_keyframes must be >= 1"};
  if (max_fixed_keyframes < 0) return Error{"max_fixed_keyframes must be >= 0"};
  if (min_keyframe_residuals < 0) return Error{"min_keyframe_residuals must be >= 0"};
  if (!(pixel_sigma_px > 0)) return Error{"pixel_sigma_px must be > 0"};
  if (!(octave_scale >= 1)) return Error{"octave_scale must be >= 1"};
  if (!(depth_focal_baseline_px_m >= 0)) return Error{"depth_focal_baseline_px_m must be >= 0"};
  if (loss != "none" && loss != "huber" && loss != "cauchy") return Error{"loss must be none, huber or cauchy"};
  if (!(loss_scale > 0)) return Error{"loss_scale must be > 0"};
  if (max_iterations < 1) return Error{"max_iterations must be >= 1"};
  if (!(max_time_s >= 0)) return Error{"max_time_s must be >= 0"};
  if (!(max_pose_change_m > 0)) return Error{"max_pose_change_m must be > 0"};
  if (!(odometry_weight >= 0)) return Error{"odometry_weight must be >= 0"};
  return Status::Ok();
}

MapRefinementResult refineAroundLoops(GlobalMap* map, const std::vector<std::uint64_t>& loop_ids,
                                      const MapRefinementParams& params) {
  const auto t0 = Clock::now();
  MapRefinementResult res;
  auto finish = [&](std::string why) {
    res.termination = std::move(why);
    res.time_ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    return res;
  };
  auto anchoredKf = [&](const KeyframeKey& k) -> const StoredKeyframe* {
    const TrajectoryMap* t = map->trajectory(k.agent, k.session);
    return t && t->anchored ? map->keyframe(k) : nullptr;
  };
  // The loops, newest first.
  const std::set<std::uint64_t> wanted(loop_ids.begin(), loop_ids.end());
  std::vector<const LoopEdge*> loops;
  for (auto it = map->loops.rbegin(); it != map->loops.rend(); ++it)
    if (wanted.count(it->id) && it->accepted && anchoredKf(it->a) && anchoredKf(it->b) &&
        static_cast<int>(loops.size()) < params.max_loops)
      loops.push_back(&*it);
  if (loops.empty()) return finish("no accepted loop between anchored trajectories");

  // Free keyframes: each loop end and its neighbours in its trajectory.
  std::set<KeyframeKey> free;
  auto addFree = [&](const KeyframeKey& k) {
    if (static_cast<int>(free.size()) < params.max_free_keyframes && anchoredKf(k)) free.insert(k);
  };
  for (const LoopEdge* l : loops) {
    for (const KeyframeKey& end : {l->a, l->b}) {
      const TrajectoryMap* t = map->trajectory(end.agent, end.session);
      auto self = t->keyframes.find(end.id);
      addFree(end);
      auto it = self;
      for (int i = 0; i < params.neighbours && it != t->keyframes.begin(); ++i) addFree(keyIn(trajOf(end), (--it)->first));
      it = self;
      for (int i = 0; i < params.neighbours && std::next(it) != t->keyframes.end(); ++i)
        addFree(keyIn(trajOf(end), (++it)->first));
    }
    for (const LoopMatch& m : l->matches) {
      addFree(keyIn(trajOf(l->a), m.kf_a));
      addFree(keyIn(trajOf(l->b), m.kf_b));
    }
  }

  // Landmarks seen by free keyframes, with all their observations.
  std::map<PointKey, PointBlock> points;
  std::vector<Obs> obs;
  std::set<std::pair<KeyframeKey, PointKey>> seen;  // one observation per (keyframe, point)
  std::map<KeyframeKey, int> outer;                  // candidate held keyframes: observations
  auto addObs = [&](const KeyframeKey& kf, std::uint32_t kp, const PointKey& pk, bool tie) {
    if (!seen.insert({kf, pk}).second) return;
    obs.push_back(Obs{kf, kp, pk, tie});
    if (!free.count(kf)) ++outer[kf];
  };
  for (const KeyframeKey& key : free) {
    const TrajectoryId tid = trajOf(key);
    const TrajectoryMap* t = map->trajectory(key.agent, key.session);
    for (LandmarkId lid : map->keyframe(key)->keyframe.keypoint_landmark) {
      if (lid == kInvalidId || points.count({tid, lid})) continue;
      PointBlock pb;
      Vec3 p_W;
      if (!landmarkWorld(*map, tid, lid, &p_W)) continue;
      std::copy(p_W.data(), p_W.data() + 3, pb.p);
      pb.traj = tid;
      pb.id = lid;
      points.emplace(PointKey{tid, lid}, pb);
      for (const Observation& o : t->landmarks.at(lid).landmark.observations) {
        const KeyframeKey ok = keyIn(tid, o.keyframe);
        const StoredKeyframe* sk = map->keyframe(ok);
        if (sk && o.keypoint < sk->keyframe.keypoints.size()) addObs(ok, o.keypoint, {tid, lid}, false);
      }
    }
  }
  // Cross-robot (and same-robot) ties from the accepted loops touching the window.
  for (const LoopEdge& l : map->loops) {
    if (!l.accepted || !anchoredKf(l.a) || !anchoredKf(l.b)) continue;
    for (const LoopMatch& m : l.matches) {
      const KeyframeKey ka = keyIn(trajOf(l.a), m.kf_a), kb = keyIn(trajOf(l.b), m.kf_b);
      if (!free.count(ka) && !free.count(kb)) continue;
      const LandmarkId la = landmarkOf(*map, ka, m.kp_a), lb = landmarkOf(*map, kb, m.kp_b);
      if (la != kInvalidId && points.count({trajOf(ka), la})) addObs(kb, m.kp_b, {trajOf(ka), la}, true);
      if (lb != kInvalidId && points.count({trajOf(kb), lb})) addObs(ka, m.kp_a, {trajOf(kb), lb}, true);
    }
  }

  // Held outer keyframes: those with the most observations of the window's points.
  std::vector<std::pair<int, KeyframeKey>> by_count;
  for (const auto& [k, n] : outer) by_count.emplace_back(-n, k);
  std::sort(by_count.begin(), by_count.end());
  std::map<KeyframeKey, PoseBlock> poses;
  auto addPose = [&](const KeyframeKey& k, bool is_free) {
    PoseBlock pb;
    pb.kf = map->keyframe(k);
    pb.before = pb.kf->T_W_C;
    const Quat& q = pb.before.quat();
    pb.q[0] = q.x(), pb.q[1] = q.y(), pb.q[2] = q.z(), pb.q[3] = q.w();
    std::copy(pb.before.translation().data(), pb.before.translation().data() + 3, pb.t);
    pb.free = is_free;
    poses.emplace(k, pb);
  };
  for (const KeyframeKey& k : free) addPose(k, true);
  for (std::size_t i = 0; i < by_count.size() && static_cast<int>(i) < params.max_fixed_keyframes; ++i)
    if (anchoredKf(by_count[i].second)) addPose(by_count[i].second, false);

  // Observations in the problem; points need two, free keyframes min_keyframe_residuals.
  std::map<PointKey, int> per_point;
  for (const Obs& o : obs)
    if (poses.count(o.kf)) ++per_point[o.point];
  std::map<KeyframeKey, int> per_kf;
  for (const Obs& o : obs)
    if (poses.count(o.kf) && per_point[o.point] >= 2) ++per_kf[o.kf];
  bool any_held = false;
  for (auto& [k, pb] : poses) {
    if (pb.free && per_kf[k] < params.min_keyframe_residuals) pb.free = false;
    any_held = any_held || (!pb.free && per_kf[k] > 0);
  }
  if (!any_held) {  // the gauge: hold the keyframe with the most observations
    auto best = std::max_element(per_kf.begin(), per_kf.end(),
                                 [](const auto& x, const auto& y) { return x.second < y.second; });
    if (best == per_kf.end()) return finish("no observations in the window");
    poses.at(best->first).free = false;
  }

  ceres::Problem::Options popt;
  popt.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  popt.manifold_ownership = ceres::TAKE_OWNERSHIP;
  ceres::Problem problem(popt);
  std::unique_ptr<ceres::LossFunction> loss = makeLoss(params);
  for (auto& [k, pb] : poses) {
    if (!per_kf.count(k)) continue;
    problem.AddParameterBlock(pb.q, 4, new ceres::EigenQuaternionManifold);
    problem.AddParameterBlock(pb.t, 3);
    if (!pb.free) {
      problem.SetParameterBlockConstant(pb.q);
      problem.SetParameterBlockConstant(pb.t);
    } else {
      ++res.free_keyframes;
    }
  }
  res.fixed_keyframes = static_cast<int>(per_kf.size()) - res.free_keyframes;
  for (const Obs& o : obs) {
    auto pose = poses.find(o.kf);
    if (pose == poses.end() || per_point[o.point] < 2) continue;
    PointBlock& pt = points.at(o.point);
    const StoredKeyframe& sk = *pose->second.kf;
    const Keypoint& kp = sk.keyframe.keypoints[o.kp];
    const double sigma = params.pixel_sigma_px * std::pow(params.octave_scale, kp.octave);
    const PinholeIntrinsics& c = sk.camera;
    problem.AddResidualBlock(
        new ceres::AutoDiffCostFunction<detail::ReprojectionCost, 2, 4, 3, 3>(
            new detail::ReprojectionCost{kp.u, kp.v, c.fx, c.fy, c.cx, c.cy, 1.0 / sigma}),
        loss.get(), pose->second.q, pose->second.t, pt.p);
    ++res.residuals;
    res.ties += o.tie;
    if (params.depth_focal_baseline_px_m > 0 && kp.depth > 0) {
      problem.AddResidualBlock(
          new ceres::AutoDiffCostFunction<detail::InverseDepthCost, 1, 4, 3, 3>(
              new detail::InverseDepthCost{1.0 / kp.depth, params.depth_focal_baseline_px_m, 1.0 / sigma}),
          loss.get(), pose->second.q, pose->second.t, pt.p);
      ++res.residuals;
    }
  }
  for (const auto& [pk, n] : per_point) res.landmarks += n >= 2;
  // The agents' odometry between consecutive keyframes of the window.
  std::set<TrajectoryId> trajs;
  for (const KeyframeKey& k : free) trajs.insert(trajOf(k));
  auto inProblem = [&](const KeyframeKey& k) { return per_kf.count(k) > 0; };
  auto isFree = [&](const KeyframeKey& k) { return inProblem(k) && poses.at(k).free; };
  for (const TrajectoryId& tid : trajs) {
    if (params.odometry_weight <= 0) break;
    const TrajectoryMap& t = map->trajectories.at(tid);
    for (const auto& [ids, e] : t.odometry) {
      const KeyframeKey a = keyIn(tid, ids.first), b = keyIn(tid, ids.second);
      if (!inProblem(a) || !inProblem(b) || (!isFree(a) && !isFree(b))) continue;
      Expected<Mat6> L = sqrtInformation(params.odometry_weight * e.information);
      if (!L) continue;
      PoseBlock& pa = poses.at(a);
      PoseBlock& pb = poses.at(b);
      problem.AddResidualBlock(RelativePoseError::create(e.T_from_to, *L), nullptr, pa.q, pa.t, pb.q, pb.t);
      ++res.odometry;
    }
  }
  if (res.free_keyframes == 0 || res.residuals == 0) return finish("nothing free in the window");

  ceres::Solver::Options opt;
  opt.linear_solver_type = ceres::SPARSE_SCHUR;
  opt.max_num_iterations = params.max_iterations;
  if (params.max_time_s > 0) opt.max_solver_time_in_seconds = params.max_time_s;
  opt.num_threads = 1;
  opt.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(opt, &problem, &summary);
  res.ran = true;
  res.iterations = static_cast<int>(summary.iterations.size());
  res.initial_cost = summary.initial_cost;
  res.final_cost = summary.final_cost;
  const bool usable = summary.IsSolutionUsable() &&
                      (summary.termination_type == ceres::CONVERGENCE ||
                       summary.termination_type == ceres::NO_CONVERGENCE) &&
                      summary.final_cost <= summary.initial_cost;
  if (!usable) return finish(std::string(ceres::TerminationTypeToString(summary.termination_type)) + ": " +
                             summary.message);
  for (const auto& [k, pb] : poses)
    if (pb.free)
      res.max_pose_change_m = std::max(res.max_pose_change_m,
                                       (Vec3(pb.t[0], pb.t[1], pb.t[2]) - pb.before.translation()).norm());
  if (res.max_pose_change_m > params.max_pose_change_m)
    return finish("discarded: a keyframe moved " + std::to_string(res.max_pose_change_m) + " m");

  // Write back: poses, then landmarks relative to their (possibly moved) anchors.
  for (auto& [k, pb] : poses)
    if (pb.free) map->keyframe(k)->T_W_C = SE3(Quat(pb.q[3], pb.q[0], pb.q[1], pb.q[2]), Vec3(pb.t[0], pb.t[1], pb.t[2]));
  for (const auto& [pk, pt] : points) {
    if (per_point[pk] < 2) continue;
    StoredLandmark& lm = map->trajectories.at(pk.first).landmarks.at(pk.second);
    const StoredKeyframe* anchor = map->keyframe(keyIn(pk.first, lm.anchor));
    lm.p_anchor = anchor->T_W_C.inverse() * Vec3(pt.p[0], pt.p[1], pt.p[2]);
  }
  // Pose-graph edges inside the window keep the refined relative poses.
  auto keep = [&](const KeyframeKey& a, const KeyframeKey& b) {
    if (!params.keep_in_pose_graph || !inProblem(a) || !inProblem(b) || (!isFree(a) && !isFree(b))) return;
    map->refined_edges[{a, b}] = map->keyframe(a)->T_W_C.inverse() * map->keyframe(b)->T_W_C;
  };
  for (const TrajectoryId& tid : trajs) {
    const TrajectoryMap& t = map->trajectories.at(tid);
    for (auto it = t.keyframes.begin(); it != t.keyframes.end() && std::next(it) != t.keyframes.end(); ++it)
      keep(keyIn(tid, it->first), keyIn(tid, std::next(it)->first));
  }
  for (const LoopEdge& l : map->loops)
    if (l.accepted) keep(l.a, l.b);
  res.applied = true;
  return finish(ceres::TerminationTypeToString(summary.termination_type));
}

TieConsistency measureLoopTies(const GlobalMap& map, double max_reproj_px) {
  TieConsistency out;
  std::vector<double> reproj, cross_reproj, dist, cross_dist;
  // Landmark of (from, kp_from) against keypoint kp_to of keyframe `to`.
  auto tie = [&](const KeyframeKey& from, std::uint32_t kp_from, const KeyframeKey& to, std::uint32_t kp_to) {
    const LandmarkId lid = landmarkOf(map, from, kp_from);
    Vec3 p_W;
    const StoredKeyframe* k = map.keyframe(to);
    const TrajectoryMap* tt = map.trajectory(to.agent, to.session);
    if (lid == kInvalidId || !k || !tt || !tt->anchored || !landmarkWorld(map, trajOf(from), lid, &p_W)) return;
    const Vec3 p_C = k->T_W_C.inverse() * p_W;
    if (p_C.z() <= 1e-6) return;
    const Keypoint& kp = k->keyframe.keypoints[kp_to];
    const double e = (k->camera.project(p_C) - Vec2(kp.u, kp.v)).norm();
    if (e > max_reproj_px) return;  // a wrong match or landmark, not the map's consistency
    const bool cross = from.agent != to.agent;
    reproj.push_back(e);
    if (cross) cross_reproj.push_back(e);
    if (kp.depth > 0) {
      const PinholeIntrinsics& c = k->camera;
      const Vec3 q_C(kp.depth * (kp.u - c.cx) / c.fx, kp.depth * (kp.v - c.cy) / c.fy, kp.depth);
      const double d = (p_C - q_C).norm();
      dist.push_back(d);
      if (cross) cross_dist.push_back(d);
    }
  };
  for (const LoopEdge& l : map.loops) {
    if (!l.accepted) continue;
    for (const LoopMatch& m : l.matches) {
      const KeyframeKey ka = keyIn(trajOf(l.a), m.kf_a), kb = keyIn(trajOf(l.b), m.kf_b);
      tie(ka, m.kp_a, kb, m.kp_b);
      tie(kb, m.kp_b, ka, m.kp_a);
    }
  }
  out.ties = static_cast<int>(reproj.size());
  out.cross_ties = static_cast<int>(cross_reproj.size());
  out.reproj_rms_px = rms(reproj);
  out.cross_reproj_rms_px = rms(cross_reproj);
  out.cross_reproj_median_px = median(cross_reproj);
  out.depth_ties = static_cast<int>(dist.size());
  out.cross_depth_ties = static_cast<int>(cross_dist.size());
  out.dist_rms_m = rms(dist);
  out.cross_dist_rms_m = rms(cross_dist);
  out.cross_dist_median_m = median(cross_dist);
  return out;
}

}  // namespace server
}  // namespace hermes
