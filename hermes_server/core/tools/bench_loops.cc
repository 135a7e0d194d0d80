// hermes_bench_loops: timing and accuracy of the loop back end on synthetic data.
// Prints JSON (stdout, and --json FILE): 17-point RANSAC per loop attempt for
// several pre-filters and outlier rates, the full keyframe path (matching +
// geometry, synthetic descriptors with 30 % wrong ones), and pose-graph
// optimisation time for N nodes.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <random>
#include <string>

#include <nlohmann/json.hpp>

#include "hermes/core/stopwatch.h"
#include "hermes/server/loop_closure.h"
#include "hermes/server/pose_graph.h"
#include "hermes_help/hermes_bench_loops.h"  // tools/help/hermes_bench_loops.txt

namespace {

using namespace hermes;
using namespace hermes::server;
using Clock = std::chrono::steady_clock;
constexpr double kDeg = M_PI / 180.0;

PinholeIntrinsics camera() {
  PinholeIntrinsics k;
  k.fx = k.fy = 450;
  k.cx = 376;
  k.cy = 240;
  k.width = 752;
  k.height = 480;
  return k;
}

Vec3 unit(std::mt19937& rng) {
  std::normal_distribution<double> n(0, 1);
  return Vec3(n(rng), n(rng), n(rng)).normalized();
}

SE3 smallPose(std::mt19937& rng, double t, double r) {
  std::uniform_real_distribution<double> u(0, 1);
  return SE3(expSO3(unit(rng) * r * u(rng)), unit(rng) * t * u(rng));
}

struct Scene {
  std::vector<Vec3> points;
  std::vector<SE3> T_W_Q, T_W_C;
  SE3 truth;
};

Scene makeScene(std::mt19937& rng, int n_points, int cams) {
  Scene s;
  std::uniform_real_distribution<double> ux(-6, 6), uy(-4, 4), uz(3, 10), ut(1, 3);
  for (int i = 0; i < n_points; ++i) s.points.emplace_back(ux(rng), uy(rng), uz(rng));
  Vec3 dir = unit(rng);
  dir.z() *= 0.3;
  s.truth = SE3(expSO3(unit(rng) * 12 * kDeg), dir.normalized() * ut(rng));
  s.T_W_Q.push_back(SE3());
  s.T_W_C.push_back(s.truth);
  for (int k = 1; k < cams; ++k) {
    s.T_W_Q.push_back(smallPose(rng, 1.0, 10 * kDeg));
    s.T_W_C.push_back(s.truth * smallPose(rng, 1.0, 10 * kDeg));
  }
  return s;
}

bool project(const SE3& T_W_C, const Vec3& p, std::mt19937& rng, Vec2* uv) {
  const Vec3 pc = T_W_C.inverse() * p;
  if (pc.z() < 0.5) return false;
  std::normal_distribution<double> n(0, 0.5);
  *uv = camera().project(pc) + Vec2(n(rng), n(rng));
  return camera().inImage(*uv, 2);
}

GeneralizedCorrespondences makeBearings(const Scene& s, std::mt19937& rng, int inliers, double outl) {
  GeneralizedCorrespondences c;
  c.focal_px = camera().fx;
  c.T_refQ_Cq = s.T_W_Q;
  for (const SE3& T : s.T_W_C) c.T_refC_Cc.push_back(s.truth.inverse() * T);
  const int nc = static_cast<int>(s.T_W_Q.size());
  std::uniform_int_distribution<int> pp(0, static_cast<int>(s.points.size()) - 1), pc(0, nc - 1);
  for (int added = 0, tries = 0; added < inliers && tries < 100000; ++tries) {
    const int a = pc(rng), b = pc(rng);
    Vec2 ua, ub;
    const Vec3& p = s.points[pp(rng)];
    if (!project(s.T_W_Q[a], p, rng, &ua) || !project(s.T_W_C[b], p, rng, &ub)) continue;
    c.bearings_q.push_back(camera().bearing(ua));
    c.bearings_c.push_back(camera().bearing(ub));
    c.cam_q.push_back(a);
    c.cam_c.push_back(b);
    ++added;
  }
  const int n_out = static_cast<int>(inliers * outl / (1 - outl));
  std::uniform_real_distribution<double> uu(0, 752), uv(0, 480);
  for (int i = 0; i < n_out; ++i) {
    c.bearings_q.push_back(camera().bearing(Vec2(uu(rng), uv(rng))));
    c.bearings_c.push_back(camera().bearing(Vec2(uu(rng), uv(rng))));
    c.cam_q.push_back(pc(rng));
    c.cam_c.push_back(pc(rng));
  }
  return c;
}

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

nlohmann::json benchRansac(const std::string& prefilter, double outliers, int reps,
                           bool opengv_refine = true) {
  std::vector<double> total, ransac, dt, dr, nees;
  int ok = 0;
  for (int rep = 0; rep < reps; ++rep) {
    std::mt19937 rng(1000 + rep);
    const Scene s = makeScene(rng, 600, 4);
    const auto corr = makeBearings(s, rng, 240, outliers);
    LoopClosureParams p;
    p.prefilter_pairs = prefilter != "none";
    if (p.prefilter_pairs) p.prefilter_solver = prefilter;
    p.ransac_max_iterations = 20000;
    p.opengv_refine = opengv_refine;
    const LoopClosureResult r = solveGeneralizedRelativePose(corr, p);
    total.push_back(r.time_ms);
    ransac.push_back(r.ransac_ms);
    if (!r.ok()) continue;
    ++ok;
    dt.push_back(translationalDistance(r.T_refQ_refC, s.truth));
    dr.push_back(angularDistance(r.T_refQ_refC, s.truth) / kDeg);
    const Vec6 e = (s.truth.inverse() * r.T_refQ_refC).log();
    nees.push_back(e.dot(r.information * e));
  }
  return {{"prefilter", prefilter}, {"opengv_refine", opengv_refine}, {"outlier_fraction", outliers}, {"correspondences_inliers", 240},
          {"cameras_per_rig", 4}, {"success_rate", double(ok) / reps},
          {"time_ms_median", median(total)}, {"ransac17_ms_median", median(ransac)},
          {"trans_err_m_median", median(dt)}, {"rot_err_deg_median", median(dr)},
          {"nees_median", median(nees)}};  // 6-dof: ~5.3 when the information is calibrated
}

std::vector<Keyframe> makeKeyframes(const std::vector<SE3>& T_W_C, const std::vector<Vec3>& pts,
                                    const std::vector<Descriptor>& desc, std::mt19937& rng) {
  std::vector<Keyframe> out;
  std::uniform_real_distribution<double> u(0, 1);
  std::uniform_int_distribution<int> bit(0, 255), pick(0, static_cast<int>(pts.size()) - 1);
  for (std::size_t c = 0; c < T_W_C.size(); ++c) {
    Keyframe kf;
    kf.id = c;
    kf.T_A_C = T_W_C[c];
    for (std::size_t i = 0; i < pts.size(); ++i) {
      Vec2 uv;
      if (!project(T_W_C[c], pts[i], rng, &uv)) continue;
      Keypoint kp;
      kp.u = static_cast<float>(uv.x());
      kp.v = static_cast<float>(uv.y());
      kf.keypoints.push_back(kp);
      Descriptor d = desc[u(rng) < 0.3 ? pick(rng) : i];  // 30 % wrong descriptors
      for (int f = 0; f < 4; ++f) {
        const int k = bit(rng);
        d[k / 8] ^= static_cast<std::uint8_t>(1u << (k % 8));
      }
      kf.descriptors.push_back(d);
      kf.keypoint_landmark.push_back(kInvalidId);
    }
    out.push_back(std::move(kf));
  }
  return out;
}

nlohmann::json benchFullPath(int points, int reps) {
  std::vector<double> total, dt, pre, rans, refine;
  int ok = 0, keypoints = 0, matches = 0;
  for (int rep = 0; rep < reps; ++rep) {
    std::mt19937 rng(2000 + rep);
    const Scene s = makeScene(rng, points, 4);
    std::vector<Descriptor> desc(points);
    std::uniform_int_distribution<int> b(0, 255);
    for (auto& d : desc) for (auto& x : d) x = static_cast<std::uint8_t>(b(rng));
    const auto q = makeKeyframes(s.T_W_Q, s.points, desc, rng);
    const auto c = makeKeyframes(s.T_W_C, s.points, desc, rng);
    keypoints = static_cast<int>(q[0].keypoints.size());
    const std::vector<PinholeIntrinsics> cams{camera()};
    LoopCloser closer{LoopClosureParams{}};
    const auto t0 = Clock::now();
    const LoopClosureResult r = closer.close(q[0], {&q[1], &q[2], &q[3]}, cams, c[0],
                                             {&c[1], &c[2], &c[3]}, cams);
    total.push_back(msSince(t0));
    pre.push_back(r.prefilter_ms);
    rans.push_back(r.ransac_ms);
    refine.push_back(r.refine_ms);
    matches = r.num_matches;
    if (!r.ok()) continue;
    ++ok;
    dt.push_back(translationalDistance(r.T_refQ_refC, s.truth));
  }
  return {{"scene_points", points}, {"keypoints_per_keyframe", keypoints}, {"keyframes_per_rig", 4},
          {"matches", matches}, {"success_rate", double(ok) / reps}, {"time_ms_median", median(total)},
          {"prefilter_ms_median", median(pre)}, {"ransac17_ms_median", median(rans)},
          {"refine_ms_median", median(refine)},
          {"trans_err_m_median", median(dt)}};
}

nlohmann::json benchPoseGraph(int nodes) {
  std::mt19937 rng(5);
  std::normal_distribution<double> n(0, 1);
  PoseGraph pg;
  const int per_agent = nodes / 2;
  std::vector<std::vector<SE3>> truth(2);
  Vec6 info_d;
  info_d << Vec3::Constant(1e4), Vec3::Constant(1e5);
  const Mat6 info = info_d.asDiagonal();
  for (std::uint32_t a = 0; a < 2; ++a) {
    SE3 T;
    for (int i = 0; i < per_agent; ++i) {
      const double th = 6 * M_PI * i / per_agent + a * M_PI;
      truth[a].push_back(SE3(expSO3(Vec3(0, 0, th + M_PI / 2)), Vec3(10 * std::cos(th) + 2 * a, 10 * std::sin(th), 0)));
      Vec6 xi;
      for (int k = 0; k < 6; ++k) xi(k) = (k < 3 ? 0.01 : 0.003) * n(rng);
      if (i > 0) T = T * truth[a][i - 1].inverse() * truth[a][i] * SE3::exp(xi);
      else T = truth[a][0];
      pg.addNode({a, 0, KeyframeId(i)}, (a ? SE3(expSO3(Vec3(0, 0, 0.1)), Vec3(0.5, 0, 0)) : SE3()) * T);
      if (i > 0) pg.addOdometryEdge({a, 0, KeyframeId(i - 1)}, {a, 0, KeyframeId(i)}, truth[a][i - 1].inverse() * truth[a][i] * SE3::exp(xi), info);
    }
  }
  int loops = 0;
  for (int i = 0; i < per_agent; i += 5) {
    for (int j = 0; j < per_agent; j += 5) {
      if ((truth[0][i].translation() - truth[1][j].translation()).norm() < 1.0) {
        pg.addLoopEdge({0, 0, KeyframeId(i)}, {1, 0, KeyframeId(j)}, truth[0][i].inverse() * truth[1][j], info);
        ++loops;
      }
    }
  }
  pg.fixFirstPoseOf(0);
  const auto t0 = Clock::now();
  auto res = pg.optimize();
  const double ms = msSince(t0);
  return {{"nodes", nodes}, {"loops", loops}, {"ok", res.ok()}, {"time_ms", ms},
          {"iterations", res.ok() ? res->iterations : 0}};
}

}  // namespace

int main(int argc, char** argv) {
  std::string json_path;
  int reps = 5;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--json" && i + 1 < argc) {
      json_path = argv[++i];
    } else if (a == "--reps" && i + 1 < argc) {
      reps = std::max(1, std::atoi(argv[++i]));
    } else if (a == "--help" || a == "-h") {
      std::fputs(hermes_help::kText, stdout);
      return 0;
    } else {
      std::fprintf(stderr, "hermes_bench_loops: unknown argument '%s'\n", a.c_str());
      return 2;
    }
  }
  nlohmann::json out;
  out["benchmark"] = "loops";
  out["ransac17"] = nlohmann::json::array();
  for (const std::string pre : {"nister", "stewenius", "eightpt"}) {
    for (double o : {0.3, 0.5}) out["ransac17"].push_back(benchRansac(pre, o, reps));
  }
  out["ransac17"].push_back(benchRansac("none", 0.3, reps));
  out["ransac17"].push_back(benchRansac("nister", 0.3, reps, false));
  out["full_path"] = nlohmann::json::array();
  for (int pts : {800, 2000}) out["full_path"].push_back(benchFullPath(pts, reps));
  out["pose_graph"] = nlohmann::json::array();
  for (int n : {500, 2000, 8000}) out["pose_graph"].push_back(benchPoseGraph(n));
  const std::string text = out.dump(2);
  std::cout << text << std::endl;
  if (!json_path.empty()) {
    std::ofstream f(json_path);
    if (!f) {
      std::fprintf(stderr, "hermes_bench_loops: cannot write %s\n", json_path.c_str());
      return 1;
    }
    f << text << "\n";
  }
  return 0;
}
