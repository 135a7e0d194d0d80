#include "hermes/system/run_results.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <sstream>

#include <nlohmann/json.hpp>

#include "hermes/core/evaluation.h"
#include "hermes/server/pose_graph_io.h"
#include "hermes/server/server_outputs.h"

namespace hermes::system {
namespace fs = std::filesystem;

namespace {

const OfflineAgent* agentOfRobot(const OfflineRun& run, RobotId robot) {
  for (const OfflineAgent& a : run.agents())
    if (a.robot && *a.robot == robot) return &a;
  return nullptr;
}

Trajectory mergedTrajectory(const OfflineRun& run, const OfflineAgent& a) {
  if (!a.robot) return {};
  return server::agentTrajectory(run.server().map(), *a.robot, a.dataset->info().T_B_C);
}

/// Ground-truth camera pose of `a` at time t (world of the ground truth).
bool gtCameraPose(const OfflineAgent& a, double t, SE3* T_W_C) {
  SE3 T_W_B;
  if (!interpolatePose(a.dataset->info().groundtruth, t, &T_W_B)) return false;
  *T_W_C = T_W_B * a.dataset->info().T_B_C;
  return true;
}

/// A loop against ground truth: its error and the true distance between the two views.
struct LoopCheck {
  double err_m = 0, err_deg = 0, gt_distance_m = 0, stamp_a = 0, stamp_b = 0;
};

std::optional<LoopCheck> checkLoop(const OfflineRun& run, const server::LoopEdge& loop) {
  const OfflineAgent* a = agentOfRobot(run, loop.a.agent);
  const OfflineAgent* b = agentOfRobot(run, loop.b.agent);
  const server::StoredKeyframe* ka = run.server().map().keyframe(loop.a);
  const server::StoredKeyframe* kb = run.server().map().keyframe(loop.b);
  if (!a || !b || !ka || !kb) return std::nullopt;
  SE3 Ta, Tb;
  if (!gtCameraPose(*a, ka->keyframe.stamp, &Ta) || !gtCameraPose(*b, kb->keyframe.stamp, &Tb))
    return std::nullopt;
  const SE3 err = (Ta.inverse() * Tb).inverse() * loop.T_a_b;
  LoopCheck c;
  c.err_m = err.translation().norm();
  c.err_deg = eval::relativeAngle(Quat::Identity(), err.quat()) * 180.0 / M_PI;
  c.gt_distance_m = (Ta.translation() - Tb.translation()).norm();
  c.stamp_a = ka->keyframe.stamp;
  c.stamp_b = kb->keyframe.stamp;
  return c;
}

void loopAccuracy(const OfflineRun& run, RunResults* res) {
  std::vector<double> trans, rot;
  LoopAccuracy acc;
  for (const server::LoopEdge& loop : run.server().map().loops) {
    if (!loop.accepted) continue;
    const OfflineAgent* a = agentOfRobot(run, loop.a.agent);
    const OfflineAgent* b = agentOfRobot(run, loop.b.agent);
    ++res->loops_per_pair[(a ? a->name : "?") + "-" + (b ? b->name : "?")];
    const std::optional<LoopCheck> c = checkLoop(run, loop);
    if (!c) continue;
    trans.push_back(c->err_m);
    rot.push_back(c->err_deg);
    if (c->err_m > 0.1 || c->err_deg > 2.0) ++acc.wrong;
    ++acc.loops;
    if (loop.a.agent != loop.b.agent) ++acc.inter_agent;
  }
  if (acc.loops == 0) return;
  acc.median_trans_m = timing::percentile(trans, 50);
  acc.p95_trans_m = timing::percentile(trans, 95);
  acc.max_trans_m = *std::max_element(trans.begin(), trans.end());
  acc.median_rot_deg = timing::percentile(rot, 50);
  res->loop_accuracy = acc;
}

/// The last pose-graph solve, edge by edge: how far each edge is from its
/// measurement (metres, degrees, chi2 of its whitened error), the weight the
/// robust loss left it, and for loops the error of the measurement itself
/// against ground truth.
void writeGraphEdges(const OfflineRun& run, std::ostream& o) {
  const server::GraphDiagnostics& g = run.server().mapManager().graphDiagnostics();
  o.precision(9);
  o << "kind,agent_a,keyframe_a,agent_b,keyframe_b,stamp_a,stamp_b,residual_m,residual_deg,chi2,"
       "weight,loop_error_m\n";
  for (const server::EdgeResidual& e : g.edges) {
    const OfflineAgent* a = agentOfRobot(run, e.a.agent);
    const OfflineAgent* b = agentOfRobot(run, e.b.agent);
    const server::StoredKeyframe* ka = run.server().map().keyframe(e.a);
    const server::StoredKeyframe* kb = run.server().map().keyframe(e.b);
    o << (e.loop ? "loop" : "odometry") << ',' << (a ? a->name : "?") << ',' << e.a.id << ','
      << (b ? b->name : "?") << ',' << e.b.id << ','
      << (ka && a ? ka->keyframe.stamp - a->clock_offset : 0.0) << ','
      << (kb && b ? kb->keyframe.stamp - b->clock_offset : 0.0) << ',' << e.error_m << ','
      << e.error_rad * 180.0 / M_PI << ',' << e.chi2 << ',' << e.weight << ',';
    if (e.loop)
      for (const server::LoopEdge& l : run.server().map().loops)
        if (l.a == e.a && l.b == e.b) {
          if (const auto c = checkLoop(run, l)) o << c->err_m;
          break;
        }
    o << '\n';
  }
}

/// The pose graph's nodes in the order of pose_graph.g2o's vertices, each with
/// its agent, dataset stamp and ground-truth camera pose (empty without one),
/// so that the graph can be solved again offline and judged (bench pose_graph).
void writeGraphNodes(const OfflineRun& run, const server::PoseGraph& graph, std::ostream& o) {
  o.precision(17);
  o << "vertex,agent,robot,session,keyframe,stamp,gt_x,gt_y,gt_z,gt_qx,gt_qy,gt_qz,gt_qw\n";
  int vertex = 0;
  for (const auto& [key, T] : graph.poses()) {
    const OfflineAgent* a = agentOfRobot(run, key.agent);
    const server::StoredKeyframe* kf = run.server().map().keyframe(key);
    o << vertex++ << ',' << (a ? a->name : "?") << ',' << key.agent << ',' << key.session << ','
      << key.id << ',' << (kf ? kf->keyframe.stamp : 0.0);
    SE3 T_W_C;
    if (a && kf && gtCameraPose(*a, kf->keyframe.stamp, &T_W_C)) {
      const Quat q = T_W_C.quat();
      o << ',' << T_W_C.translation().x() << ',' << T_W_C.translation().y() << ','
        << T_W_C.translation().z() << ',' << q.x() << ',' << q.y() << ',' << q.z() << ',' << q.w();
    } else {
      o << ",,,,,,,";
    }
    o << '\n';
  }
}

std::string fmtNumber(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

template <typename F>
Status writeFile(const fs::path& path, F&& body) {
  std::ofstream out(path);
  if (!out) return Error{"cannot write " + path.string()};
  body(out);
  out.close();
  if (!out) return Error{"error writing " + path.string()};
  return Status::Ok();
}

/// Each robot's own idea of its place in the world (OfflineAgent::global_track)
/// against ground truth under the merged map's one alignment.
void globalPoseAccuracy(const OfflineRun& run, const eval::Alignment& alignment, RunMetrics* m) {
  const eval::EvalParams& ep = run.params().run.eval;
  for (AgentMetrics& am : m->per_agent) {
    const auto it = std::find_if(run.agents().begin(), run.agents().end(),
                                 [&](const OfflineAgent& o) { return o.name == am.agent; });
    if (it == run.agents().end()) continue;
    const OfflineAgent& a = *it;
    am.global_pose_updates = static_cast<std::int64_t>(a.pipeline->globalPose().updates());
    const Trajectory& gt = a.dataset->info().groundtruth;
    if (gt.empty() || a.global_track.size() < 2) continue;
    auto ev = eval::evaluateTrajectory(gt, a.global_track, ep, a.name);
    if (!ev.ok() || ev->assoc.t.empty()) continue;
    const eval::AteResult r = eval::ateWithAlignment(ev->assoc, alignment);
    if (r.trans_errors_m.empty()) continue;
    am.global_pose_rmse_m = r.trans_m.rmse;
    am.global_pose_final_m = r.trans_errors_m.back();
  }
}

/// The one map: robots placed, its size, the paths flown in it, loops between robots.
MapSummary summarizeMap(const OfflineRun& run, std::int64_t agents_merged) {
  MapSummary s;
  const server::GlobalMap& map = run.server().map();
  s.robots = agents_merged;
  s.prior_robots = run.server().mapManager().priorAgents();
  s.keyframes = static_cast<std::int64_t>(map.keyframeCount());
  s.landmarks = static_cast<std::int64_t>(map.landmarkCount());
  for (const server::LoopEdge& l : map.loops)
    if (l.accepted && l.a.agent != l.b.agent) ++s.loops_inter_robot;
  std::vector<Vec3> positions;
  for (const OfflineAgent& a : run.agents()) {
    const Trajectory t = mergedTrajectory(run, a);
    if (t.empty()) continue;
    double path = 0;
    for (std::size_t i = 0; i < t.size(); ++i) {
      positions.push_back(t[i].T_W_B.translation());
      if (i > 0) path += (positions.back() - t[i - 1].T_W_B.translation()).norm();
    }
    s.robot_path_m[a.name] = path;
    s.path_m += path;
  }
  if (positions.empty()) return s;
  // The box along the positions' principal axes, so that its sides do not depend on how
  // the world frame happens to be turned.
  Vec3 mean = Vec3::Zero();
  for (const Vec3& p : positions) mean += p;
  mean /= double(positions.size());
  Mat3 cov = Mat3::Zero();
  for (const Vec3& p : positions) cov += (p - mean) * (p - mean).transpose();
  const Mat3 axes = Eigen::SelfAdjointEigenSolver<Mat3>(cov).eigenvectors();
  Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (const Vec3& p : positions) {
    const Vec3 q = axes.transpose() * (p - mean);
    lo = lo.cwiseMin(q);
    hi = hi.cwiseMax(q);
  }
  s.extent_m = hi - lo;
  std::sort(s.extent_m.data(), s.extent_m.data() + 3, std::greater<double>());
  return s;
}

/// Uncompressed bytes of one camera frame of `a`: a grey stereo pair, or RGB + 16-bit depth.
std::int64_t cameraFrameBytes(const OfflineAgent& a) {
  const DatasetInfo& info = a.dataset->info();
  const std::int64_t pixels = std::int64_t(info.K.width) * info.K.height;
  return isStereo(info.kind) ? 2 * pixels : pixels * (3 + 2);
}

}  // namespace

RunResults evaluateRun(const OfflineRun& run) {
  RunResults res;
  RunMetrics& m = res.metrics;
  const server::Server& srv = run.server();
  const RunMetrics sm = server::serverMetrics(srv);
  m.loops_accepted = sm.loops_accepted;
  m.loops_rejected = sm.loops_rejected;
  m.agents_merged = sm.agents_merged;
  m.frames_refused = sm.frames_refused;
  m.relocalised = sm.relocalised;
  m.robots_new = sm.robots_new;
  m.loops_bridged = sm.loops_bridged;
  if (run.stoppedEarly()) {
    m.incomplete = true;
    m.stopped_because = "stopped before the end of the data (interrupted)";
  }
  TimingStats timings = srv.timings();
  const eval::EvalParams& ep = run.params().run.eval;
  std::vector<eval::AgentTrajectories> merged;
  std::int64_t bytes_total = 0;
  for (const OfflineAgent& a : run.agents()) {
    timings.merge(a.pipeline->timings());
    AgentMetrics am = a.pipeline->metrics();
    am.frames_skipped = a.skips.total();
    am.frames_skipped_causes = a.skips.byCause();
    am.bytes = static_cast<std::int64_t>(a.pipeline->uplink()->stats().bytes_sent);
    if (run.network())  // what really went onto a link (a robot without a route sends nothing)
      am.bytes = std::llround(run.network()->ownBytes(static_cast<std::size_t>(&a - run.agents().data())));
    for (const AgentResetRecord& r : a.resets) {  // the pipelines before its resets
      if (!run.network()) *am.bytes += r.bytes_sent_before;
      am.submaps_sent = am.submaps_sent.value_or(0) + r.submaps_sent_before;
    }
    bytes_total += *am.bytes;
    if (run.downlink())
      am.downlink_bytes = static_cast<std::int64_t>(
          run.downlink()->bytesTo(static_cast<std::size_t>(&a - run.agents().data())));
    am.submaps_applied = 0;
    if (a.robot) {
      if (const AgentStats* st = srv.bookkeeper().stats(*a.robot))
        am.submaps_applied = static_cast<std::int64_t>(st->submaps_applied);
      server::fillHeldLoad(srv, *a.robot, &am);
      server::fillSessions(srv.bookkeeper(), *a.robot, &am);
    }
    const Trajectory& gt = a.dataset->info().groundtruth;
    if (!gt.empty() && !a.pipeline->trajectory().empty()) {
      auto ev = eval::evaluateTrajectory(gt, a.pipeline->trajectory(), ep, a.name);
      if (ev.ok())
        am.raw_ate_rmse_m = ev->ate.trans_m.rmse;
      else
        res.warnings.push_back("raw trajectory of " + a.name + ": " + ev.error());
    }
    m.per_agent.push_back(am);
    Trajectory mt = mergedTrajectory(run, a);
    if (!gt.empty() && !mt.empty()) merged.push_back({a.name, gt, std::move(mt)});
  }
  m.bytes_total = bytes_total;
  const BandwidthSummary bw = summarizeBandwidth(run.bandwidth());
  m.kBps_mean = bw.kBps_mean;
  m.kBps_peak = bw.kBps_peak;
  m.timings_ms = timings.summary();
  if (!merged.empty()) {
    auto ev = eval::evaluateAgents(merged, ep, /*allow_partial=*/true);
    if (ev.ok()) {
      fillAccuracy(*ev, ep, &m);
      globalPoseAccuracy(run, ev->merged_alignment, &m);
      for (const eval::AgentFailure& f : ev->failed)
        res.warnings.push_back("merged trajectory of " + f.name + ": " + f.error);
    } else {
      res.warnings.push_back("merged evaluation: " + ev.error());
    }
  }
  loopAccuracy(run, &res);
  res.map = summarizeMap(run, m.agents_merged.value_or(0));
  for (const OfflineAgent& a : run.agents()) {
    res.camera_bytes += std::int64_t(a.next) * cameraFrameBytes(a);
    res.raw_streaming_bytes += a.pipeline->windows().window_bytes;
    for (const AgentResetRecord& r : a.resets) res.raw_streaming_bytes += r.window_bytes_before;
  }
  res.durability = summarizeDurability(run);
  res.relay = summarizeRelay(run);
  return res;
}

nlohmann::json resultsJson(const RunResults& res) {
  nlohmann::json j = res.metrics;
  if (res.loop_accuracy) {
    const LoopAccuracy& l = *res.loop_accuracy;
    j["loop_accuracy"] = {{"loops", l.loops},
                          {"inter_agent", l.inter_agent},
                          {"median_trans_m", l.median_trans_m},
                          {"median_rot_deg", l.median_rot_deg},
                          {"p95_trans_m", l.p95_trans_m},
                          {"max_trans_m", l.max_trans_m},
                          {"wrong", l.wrong},
                          {"precision", 1.0 - double(l.wrong) / double(l.loops)}};
  }
  j["loops_per_pair"] = res.loops_per_pair;
  const MapSummary& g = res.map;
  j["global_map"] = {{"robots", g.robots},
                     {"keyframes", g.keyframes},
                     {"landmarks", g.landmarks},
                     {"loops_inter_robot", g.loops_inter_robot},
                     {"path_m", g.path_m},
                     {"robot_path_m", g.robot_path_m},
                     {"extent_m", {g.extent_m.x(), g.extent_m.y(), g.extent_m.z()}}};
  j["camera_bytes_total"] = res.camera_bytes;
  j["raw_streaming_bytes_total"] = res.raw_streaming_bytes;
  if (!res.warnings.empty()) j["warnings"] = res.warnings;
  if (res.durability) j.update(durabilityJson(*res.durability));
  if (res.relay) j["relay"] = relayJson(*res.relay);
  return j;
}

Status writeRunResults(const OfflineRun& run, const RunResults& res, const std::string& out_dir) {
  const fs::path out(out_dir), traj_dir = out / "trajectories";
  std::error_code ec;
  fs::create_directories(traj_dir, ec);
  if (ec) return Error{"cannot create " + traj_dir.string() + ": " + ec.message()};
  const eval::EvalParams& ep = run.params().run.eval;
  std::vector<eval::AgentTrajectories> merged;
  for (const OfflineAgent& a : run.agents()) {
    if (Status s = writeTumTrajectory((traj_dir / (a.name + "_raw.tum")).string(),
                                      a.pipeline->trajectory());
        !s)
      return s;
    if (!a.global_track.empty())
      if (Status s = writeTumTrajectory((traj_dir / (a.name + "_global.tum")).string(), a.global_track); !s)
        return s;
    Trajectory mt = mergedTrajectory(run, a);
    if (mt.empty()) continue;
    if (Status s = writeTumTrajectory((traj_dir / (a.name + "_merged.tum")).string(), mt); !s)
      return s;
    if (!a.dataset->info().groundtruth.empty())
      merged.push_back({a.name, a.dataset->info().groundtruth, std::move(mt)});
  }
  if (Status s = writeFile(out / "metrics.json",
                           [&](std::ostream& o) { o << resultsJson(res).dump(2) << '\n'; });
      !s)
    return s;
  if (Status s = writeBandwidthCsv((out / "bandwidth.csv").string(), run.bandwidth()); !s) return s;
  if (Status s = writeFile(out / "uplink_estimate.csv",
                           [&](std::ostream& o) {
                             o << "time_s,agent,estimate_kBps\n";
                             for (const auto& [name, series] : run.estimates())
                               for (const auto& [t, bps] : series)
                                 o << t << ',' << name << ',' << bps / 1000.0 << '\n';
                           });
      !s)
    return s;
  if (!run.health().empty())
    if (Status s = writeFile(out / "health.csv",
                             [&](std::ostream& o) {
                               o << "time_s,wall_s,server_up,state_bytes,rss_bytes,keyframes,landmarks,pending,"
                                    "merged,submaps,submap_ms_median,submap_ms_p95,agents_merged,flying\n";
                               for (const HealthSample& h : run.health())
                                 o << h.time_s << ',' << h.wall_s << ',' << h.server_up << ',' << h.state_bytes << ','
                                   << h.rss_bytes << ',' << h.keyframes << ',' << h.landmarks << ',' << h.pending
                                   << ',' << h.merged << ',' << h.submaps << ',' << h.submap_ms_median << ','
                                   << h.submap_ms_p95 << ',' << h.agents_merged << ',' << h.flying << '\n';
                             });
        !s)
      return s;
  // Error over time: every merged pose's error under the run's one common
  // alignment (kind merged), and every odometry pose's error with the agent's
  // odometry aligned on its own (kind odometry).
  std::ostringstream ate;
  ate << "time_s,agent,kind,error_m\n";
  for (const OfflineAgent& a : run.agents()) {
    const Trajectory& gt = a.dataset->info().groundtruth;
    if (gt.empty() || a.pipeline->trajectory().empty()) continue;
    auto ev = eval::evaluateTrajectory(gt, a.pipeline->trajectory(), ep, a.name);
    if (!ev.ok()) continue;
    for (std::size_t i = 0; i < ev->ate.trans_errors_m.size(); ++i)
      ate << ev->assoc.t[i] - a.clock_offset << ',' << a.name << ",odometry,"
          << ev->ate.trans_errors_m[i] << '\n';
  }
  if (!merged.empty()) {
    auto ev = eval::evaluateAgents(merged, ep, true);
    if (ev.ok())
      for (const eval::TrajectoryEval& a : ev->agents) {
        const eval::AteResult r = eval::ateWithAlignment(a.assoc, ev->merged_alignment);
        const double t0 = [&] {
          for (const OfflineAgent& o : run.agents())
            if (o.name == a.name) return o.clock_offset;
          return 0.0;
        }();
        for (std::size_t i = 0; i < r.trans_errors_m.size(); ++i)
          ate << a.assoc.t[i] - t0 << ',' << a.name << ",merged," << r.trans_errors_m[i] << '\n';
      }
    // kind global: each robot's own world pose as it knew it, same alignment.
    if (ev.ok())
      for (const OfflineAgent& o : run.agents()) {
        const Trajectory& gt = o.dataset->info().groundtruth;
        if (gt.empty() || o.global_track.size() < 2) continue;
        auto g = eval::evaluateTrajectory(gt, o.global_track, ep, o.name);
        if (!g.ok()) continue;
        const eval::AteResult r = eval::ateWithAlignment(g->assoc, ev->merged_alignment);
        for (std::size_t i = 0; i < r.trans_errors_m.size(); ++i)
          ate << g->assoc.t[i] - o.clock_offset << ',' << o.name << ",global," << r.trans_errors_m[i] << '\n';
      }
  }
  if (Status s = writeFile(out / "ate_over_time.csv", [&](std::ostream& o) { o << ate.str(); }); !s)
    return s;
  if (Status s = writeFile(out / "loops.csv",
                           [&](std::ostream& o) {
                             o.precision(15);
                             o << "agent_a,keyframe_a,agent_b,keyframe_b,accepted,tx,ty,tz,"
                                  "inliers,depth_inliers,sigma_t_m,stamp_a,stamp_b,gt_distance_m,"
                                  "error_m,error_deg\n";
                             for (const server::LoopEdge& l : run.server().map().loops) {
                               const OfflineAgent* a = agentOfRobot(run, l.a.agent);
                               const OfflineAgent* b = agentOfRobot(run, l.b.agent);
                               o << (a ? a->name : "?") << ',' << l.a.id << ','
                                 << (b ? b->name : "?") << ',' << l.b.id << ','
                                 << (l.accepted ? 1 : 0) << ',' << l.T_a_b.translation().x()
                                 << ',' << l.T_a_b.translation().y() << ','
                                 << l.T_a_b.translation().z() << ',' << l.inliers << ','
                                 << l.depth_inliers << ','
                                 << std::sqrt(std::max(0.0, Mat3(l.covariance.topLeftCorner<3, 3>())
                                                                .selfadjointView<Eigen::Upper>()
                                                                .eigenvalues()
                                                                .maxCoeff()));
                               if (const auto c = checkLoop(run, l))  // empty without ground truth
                                 o << ',' << c->stamp_a << ',' << c->stamp_b << ','
                                   << c->gt_distance_m << ',' << c->err_m << ',' << c->err_deg;
                               else
                                 o << ",,,,,";
                               o << '\n';
                             }
                           });
      !s)
    return s;
  if (Status s = writeFile(out / "pose_graph_edges.csv",
                           [&](std::ostream& o) { writeGraphEdges(run, o); });
      !s)
    return s;
  if (Expected<server::PoseGraph> graph = run.server().mapManager().buildPoseGraph()) {
    if (Status s = server::writePoseGraphG2o(*graph, (out / "pose_graph.g2o").string()); !s) return s;
    if (Status s = writeFile(out / "pose_graph_nodes.csv",
                             [&](std::ostream& o) { writeGraphNodes(run, *graph, o); });
        !s)
      return s;
  }  // else nothing anchored: no graph to write
  if (Status s = run.server().map().save((out / "global_map.hgm").string()); !s) return s;
  return server::writePly((out / "global_map.ply").string(),
                          run.server().map().landmarkPositionsWorld(), /*binary=*/true);
}

Status saveMapToResume(const server::Server& server, const std::string& dir) {
  std::error_code ec;
  fs::remove_all(dir, ec);
  if (ec) return Error{"cannot empty " + dir + ": " + ec.message()};
  server::CheckpointParams params;
  params.dir = dir;
  auto store = server::CheckpointStore::open(params);
  if (!store) return Error{store.error()};
  auto written = store->write(server.saveState());
  if (!written) return Error{written.error()};
  return Status::Ok();
}

Status writeLoopAttempts(const OfflineRun& run, const std::vector<server::LoopAttempt>& attempts,
                         const std::string& path) {
  return writeFile(path, [&](std::ostream& o) {
    o.precision(9);
    o << "agent,keyframe,stamp,candidate_agent,candidate_keyframe,candidate_stamp,score,"
         "normalized_score,island_size,source,status,reason,matches,inliers,gt_distance_m,gt_angle_deg,"
         "prefiltered,ransac_iterations,ransac_enough_at,ms,prefilter_ms,ransac_ms,refine_ms\n";
    auto where = [&](const KeyframeKey& k, const OfflineAgent** agent) -> double {
      *agent = agentOfRobot(run, k.agent);
      const server::StoredKeyframe* kf = run.server().map().keyframe(k);
      return kf ? kf->keyframe.stamp : std::nan("");
    };
    for (const server::LoopAttempt& a : attempts) {
      const OfflineAgent* qa = nullptr;
      const double qs = where(a.query, &qa);
      o << (qa ? qa->name : "?") << ',' << a.query.id << ',' << (qa ? qs - qa->clock_offset : qs);
      if (!a.candidate) {
        o << ",,,,,,,,no candidate,,,,,,,,,,,,\n";
        continue;
      }
      const OfflineAgent* ca = nullptr;
      const double cs = where(a.candidate->key, &ca);
      std::string reason = a.reason;
      std::replace(reason.begin(), reason.end(), ',', ';');
      o << ',' << (ca ? ca->name : "?") << ',' << a.candidate->key.id << ','
        << (ca ? cs - ca->clock_offset : cs) << ',' << a.candidate->score << ','
        << a.candidate->normalized_score << ',' << a.candidate->island_size << ','
        << (a.spatial ? "map" : "place") << ',' << server::toString(a.status) << ',' << reason << ',' << a.matches << ',' << a.inliers << ',';
      SE3 Tq, Tc;
      if (qa && ca && gtCameraPose(*qa, qs, &Tq) && gtCameraPose(*ca, cs, &Tc)) {
        const SE3 d = Tq.inverse() * Tc;
        o << d.translation().norm() << ',' << rotationAngle(d.rotation()) * 180.0 / M_PI;
      } else {
        o << ',';
      }
      o << ',' << a.prefiltered << ',' << a.ransac_iterations << ',' << a.ransac_enough_at << ','
        << a.ms << ',' << a.prefilter_ms << ',' << a.ransac_ms << ',' << a.refine_ms << '\n';
    }
  });
}

std::string formatReport(const OfflineRun& run, const RunResults& res) {
  const RunMetrics& m = res.metrics;
  const MapSummary& g = res.map;
  std::ostringstream o;
  char buf[320];
  auto ll = [](std::int64_t v) { return static_cast<long long>(v); };
  auto cell = [](const std::optional<double>& v) {  // [m] -> "1.23" [cm], "-" when absent
    char c[32];
    if (!v) return std::string("-");
    std::snprintf(c, sizeof c, "%.2f", *v * 100.0);
    return std::string(c);
  };
  std::string link;
  if (run.network())
    link = "scenario " + run.params().link.scenario;
  else if (run.link().trace().unlimited())
    link = "unlimited";
  else if (run.params().link.trace.empty())
    link = fmtNumber(run.params().link.bandwidth_mbitps) + " Mbit/s shared";
  else
    link = "trace " + run.params().link.trace;

  // What merging gave first: one map holding every robot, which no robot has alone.
  const std::size_t robots = run.agents().size();
  std::string prior;
  if (g.prior_robots > 0) prior = " of a prior map (" + std::to_string(g.prior_robots) + " robots before)";
  std::snprintf(buf, sizeof buf, "one map: %lld of %zu robots placed in one world frame%s\n", ll(g.robots), robots,
                !prior.empty() ? prior.c_str() : robots > 1 ? " (alone, no robot knows where the others are)" : "");
  o << buf;
  std::snprintf(buf, sizeof buf,
                "  map       %lld keyframes, %lld landmarks; %.1f m flown in it, within %.1f x %.1f x %.1f m\n",
                ll(g.keyframes), ll(g.landmarks), g.path_m, g.extent_m.x(), g.extent_m.y(), g.extent_m.z());
  o << buf;
  std::snprintf(buf, sizeof buf, "  loops     %lld between robots (%lld accepted in all, %lld rejected)\n",
                ll(g.loops_inter_robot), ll(m.loops_accepted.value_or(0)), ll(m.loops_rejected.value_or(0)));
  o << buf;
  const double sent_mb = double(m.bytes_total.value_or(0)) / 1e6;
  std::snprintf(buf, sizeof buf, "  sent      %.1f MB (link %s)", sent_mb, link.c_str());
  o << buf;
  o << '\n';
  if (res.raw_streaming_bytes > 0) {
    std::snprintf(buf, sizeof buf, "            %.0f %% of the %.1f MB raw streaming of the same maps would send\n",
                  100.0 * sent_mb * 1e6 / double(res.raw_streaming_bytes), double(res.raw_streaming_bytes) / 1e6);
    o << buf;
  }
  if (res.camera_bytes > 0) {
    std::snprintf(buf, sizeof buf, "            %.2f %% of the %.0f MB of images the cameras took (uncompressed)\n",
                  100.0 * sent_mb * 1e6 / double(res.camera_bytes), double(res.camera_bytes) / 1e6);
    o << buf;
  }
  if (run.downlink()) {  // the map back to the robots (server.downlink)
    std::int64_t down = 0, placed = 0;
    for (const AgentMetrics& a : m.per_agent) {
      down += a.downlink_bytes.value_or(0);
      placed += a.borrowed_relocalisations.value_or(0);
    }
    std::snprintf(buf, sizeof buf,
                  "  received  %.1f kB of the map back (%.0f B/s per robot at most); %lld session(s) placed by it\n",
                  double(down) / 1e3, run.params().server.downlink.bytes_per_s, ll(placed));
    o << buf;
  }
  std::snprintf(buf, sizeof buf, "  %-14s %20s   %24s   %9s\n", "ATE [cm]", "odometry (own frame)",
                "merged (one map for all)", "flown [m]");
  o << buf;
  for (const AgentMetrics& a : m.per_agent) {
    const auto path = g.robot_path_m.find(a.agent);
    std::string flown = "-";
    if (path != g.robot_path_m.end()) {
      std::snprintf(buf, sizeof buf, "%.1f", path->second);
      flown = buf;
    }
    std::snprintf(buf, sizeof buf, "  %-14s %20s   %24s   %9s\n", a.agent.c_str(), cell(a.raw_ate_rmse_m).c_str(),
                  cell(a.merged_ate_rmse_m).c_str(), flown.c_str());
    o << buf;
  }
  std::snprintf(buf, sizeof buf, "  %-14s %20s   %24s\n", "all robots", "", cell(m.ate_rmse_m).c_str());
  o << buf;

  const agent::OdometryCorruptionParams& c = run.params().corrupt;
  if (c.active()) {  // a fault the test hooks injected (config corrupt.*): say so beside the numbers it moves
    if (c.kind == "jump")
      std::snprintf(buf, sizeof buf,
                    "  injected  %s's odometry jumps %.2f m / %.1f deg at %.1f s (a wrong relocalisation; corrupt.*)\n",
                    c.agent.c_str(), c.jump_m, c.jump_deg, c.at_s);
    else
      std::snprintf(buf, sizeof buf,
                    "  injected  %s's odometry drifts %.1f %% of its path for %.0f s from %.1f s (corrupt.*)\n",
                    c.agent.c_str(), 100.0 * c.drift_fraction, c.drift_duration_s, c.at_s);
    o << buf;
  }

  // The details.
  std::snprintf(buf, sizeof buf, "uplink: %.1f kB in all, mean %.1f kB/s, peak %.1f kB/s\n",
                double(m.bytes_total.value_or(0)) / 1000.0, m.kBps_mean.value_or(0), m.kBps_peak.value_or(0));
  o << buf;
  for (const AgentMetrics& a : m.per_agent) {
    std::snprintf(buf, sizeof buf, "  %-14s lost %5.1f %%  submaps sent %lld applied %lld deferred %lld  %.1f kB\n",
                  a.agent.c_str(), 100.0 * a.lost_rate.value_or(0), ll(a.submaps_sent.value_or(0)),
                  ll(a.submaps_applied.value_or(0)), ll(a.submaps_deferred.value_or(0)),
                  double(a.bytes.value_or(0)) / 1000.0);
    o << buf;
    if (a.global_pose_final_m) {  // what the robot itself knew of its place in the world
      std::snprintf(buf, sizeof buf,
                    "  %-14s own global pose: %s cm at its last frame, %s cm RMSE over time, %lld update(s)\n",
                    "", cell(a.global_pose_final_m).c_str(), cell(a.global_pose_rmse_m).c_str(),
                    ll(a.global_pose_updates.value_or(0)));
      o << buf;
    }
    if (a.trouble_windows.value_or(0) > 0) {  // windows distilled with more keyframes / budget
      std::snprintf(buf, sizeof buf, "  %-14s in trouble: %lld window(s), %lld weak frame(s)\n", "",
                    ll(*a.trouble_windows), ll(a.weak_frames.value_or(0)));
      o << buf;
    }
  }
  if (res.loop_accuracy) {
    const LoopAccuracy& l = *res.loop_accuracy;
    std::snprintf(buf, sizeof buf,
                  "loop accuracy vs ground truth: %zu loops (%zu between robots), median %.2f cm / "
                  "%.3f deg, p95 %.2f cm, %zu off by > 10 cm or 2 deg\n",
                  l.loops, l.inter_agent, l.median_trans_m * 100, l.median_rot_deg,
                  l.p95_trans_m * 100, l.wrong);
    o << buf;
  }
  if (res.durability) o << formatDurability(*res.durability);
  if (res.relay) o << formatRelay(*res.relay);
  for (const std::string& w : res.warnings) o << "warning: " << w << '\n';
  return o.str();
}

}  // namespace hermes::system
