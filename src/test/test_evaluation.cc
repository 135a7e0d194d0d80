#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <random>

#include "hermes/core/eval_io.h"
#include "hermes/core/evaluation.h"

using namespace hermes;
using namespace hermes::eval;

namespace {

SE3 randomPose(std::mt19937& rng, double trans_scale) {
  std::normal_distribution<double> n(0, 1);
  return SE3(expSO3(Vec3(n(rng), n(rng), n(rng))),
             trans_scale * Vec3(n(rng), n(rng), n(rng)));
}

/// Helix with turning orientation: t_i = t0 + i * dt.
Trajectory helix(size_t n, double dt, double t0 = 0) {
  Trajectory tr;
  for (size_t i = 0; i < n; ++i) {
    const double t = t0 + double(i) * dt;
    tr.push_back({t, SE3(expSO3(Vec3(0.1 * std::sin(t), 0.05, 0.4 * t)),
                         Vec3(3 * std::cos(0.4 * t), 2 * std::sin(0.4 * t), 0.3 * t))});
  }
  return tr;
}

}  // namespace

TEST(Umeyama, RecoversRandomSim3AndNeverReflects) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-5, 5);
  std::vector<Vec3> src, dst;
  const SE3 T = randomPose(rng, 3.0);
  const double s = 2.7;
  for (int i = 0; i < 50; ++i) {
    src.emplace_back(u(rng), u(rng), u(rng));
    dst.push_back(s * (T.quat() * src.back()) + T.translation());
  }
  auto a = umeyama(src, dst, true);
  ASSERT_TRUE(a.ok()) << a.error();
  EXPECT_NEAR(a->scale, s, 1e-10);
  EXPECT_LT((a->T_gt_est.matrix() - T.matrix()).norm(), 1e-10);

  // A mirrored target: the best proper rotation must still have det +1.
  std::vector<Vec3> mirrored;
  for (const Vec3& p : src) mirrored.emplace_back(p.x(), p.y(), -p.z());
  auto m = umeyama(src, mirrored, false);
  ASSERT_TRUE(m.ok());
  EXPECT_NEAR(m->T_gt_est.rotation().determinant(), 1.0, 1e-12);

  EXPECT_FALSE(umeyama({src[0], src[1]}, {dst[0], dst[1]}, false).ok());
  EXPECT_FALSE(umeyama(src, {dst[0], dst[1], dst[2]}, false).ok());
  std::vector<Vec3> same(5, Vec3(1, 2, 3));
  EXPECT_FALSE(umeyama(same, same, true).ok());
}

TEST(Ate, KnownRigidOffsetAlignsToZero) {
  std::mt19937 rng(1);
  const Trajectory gt = helix(400, 0.05);
  for (int trial = 0; trial < 5; ++trial) {
    const SE3 T_est_gt = randomPose(rng, 10.0);
    Trajectory est;
    for (const auto& p : gt) est.push_back({p.t, T_est_gt * p.T_W_B});
    auto ev = evaluateTrajectory(gt, est, EvalParams{});
    ASSERT_TRUE(ev.ok()) << ev.error();
    EXPECT_EQ(ev->assoc.matched(), 400u);
    EXPECT_LT(ev->ate.trans_m.rmse, 1e-9);
    EXPECT_LT(ev->ate.trans_m.max, 1e-9);
    EXPECT_LT(ev->ate.rot_deg.max, 1e-7);
    EXPECT_LT((ev->ate.alignment.T_gt_est.matrix() - T_est_gt.inverse().matrix()).norm(), 1e-9);
    EXPECT_LT(ev->rpe.trans_m.max, 1e-9);
    // Without alignment the offset is fully visible.
    EvalParams none;
    none.align = AlignMode::kNone;
    auto raw = evaluateTrajectory(gt, est, none);
    ASSERT_TRUE(raw.ok());
    EXPECT_GT(raw->ate.trans_m.rmse, 0.1);
    // Aligning the first pose also removes a rigid offset exactly.
    EvalParams first;
    first.align = AlignMode::kFirstPose;
    auto f = evaluateTrajectory(gt, est, first);
    ASSERT_TRUE(f.ok());
    EXPECT_LT(f->ate.trans_m.max, 1e-9);
  }
}

TEST(Ate, EverySecondPoseOffsetGivesKnownRmse) {
  const Trajectory gt = helix(300, 0.02);
  Trajectory est = gt;
  for (size_t i = 0; i < est.size(); i += 2)
    est[i].T_W_B = SE3(est[i].T_W_B.quat(), est[i].T_W_B.translation() + Vec3(0.1, 0, 0));
  EvalParams none;
  none.align = AlignMode::kNone;
  auto ev = evaluateTrajectory(gt, est, none);
  ASSERT_TRUE(ev.ok());
  EXPECT_NEAR(ev->ate.trans_m.rmse, 0.1 / std::sqrt(2.0), 1e-12);
  EXPECT_NEAR(ev->ate.trans_m.mean, 0.05, 1e-12);
  EXPECT_NEAR(ev->ate.trans_m.median, 0.05, 1e-12);  // 150 zeros, 150 x 0.1
  EXPECT_NEAR(ev->ate.trans_m.max, 0.1, 1e-12);
  EXPECT_NEAR(ev->ate.trans_m.std, 0.05, 1e-12);
}

TEST(Ate, SymmetricPerturbationSurvivesSe3AlignmentExactly) {
  // The robot pauses: poses 2k and 2k+1 share a position; the estimate moves them
  // +a and -a along z. The optimal rigid alignment is then the identity, and every
  // pose is off by exactly a.
  const Trajectory base = helix(200, 0.1);
  Trajectory gt, est;
  const double a = 0.037;
  for (size_t k = 0; k < base.size(); ++k) {
    for (int s : {+1, -1}) {
      const double t = double(gt.size()) * 0.01;
      gt.push_back({t, base[k].T_W_B});
      est.push_back({t, SE3(base[k].T_W_B.quat(),
                            base[k].T_W_B.translation() + Vec3(0, 0, s * a))});
    }
  }
  auto ev = evaluateTrajectory(gt, est, EvalParams{});
  ASSERT_TRUE(ev.ok()) << ev.error();
  EXPECT_NEAR(ev->ate.trans_m.rmse, a, 1e-9);
  EXPECT_NEAR(ev->ate.trans_m.min, a, 1e-9);
  EXPECT_LT(ev->ate.trans_m.std, 1e-9);
}

TEST(Ate, ConstantNormNoiseGivesItsNorm) {
  std::mt19937 rng(3);
  std::normal_distribution<double> n(0, 1);
  const Trajectory gt = helix(500, 0.01);
  Trajectory est = gt;
  for (auto& p : est) {
    const Vec3 dir = Vec3(n(rng), n(rng), n(rng)).normalized();
    p.T_W_B = SE3(p.T_W_B.quat(), p.T_W_B.translation() + 0.05 * dir);
  }
  EvalParams none;
  none.align = AlignMode::kNone;
  auto ev = evaluateTrajectory(gt, est, none);
  ASSERT_TRUE(ev.ok());
  EXPECT_NEAR(ev->ate.trans_m.rmse, 0.05, 1e-12);
  EXPECT_NEAR(ev->ate.trans_m.max, 0.05, 1e-12);
  // SE(3) alignment can only reduce the error (identity is a feasible transform).
  auto se3 = evaluateTrajectory(gt, est, EvalParams{});
  ASSERT_TRUE(se3.ok());
  EXPECT_LE(se3->ate.trans_m.rmse, 0.05 + 1e-12);
  EXPECT_GT(se3->ate.trans_m.rmse, 0.045);
}

TEST(Ate, Sim3RecoversKnownScale) {
  std::mt19937 rng(5);
  const Trajectory gt = helix(300, 0.05);
  const SE3 T_est_gt = randomPose(rng, 4.0);
  const double c = 0.37;  // estimate is in different units: p_est = c * (R p + t)
  Trajectory est;
  for (const auto& p : gt) {
    const SE3 m = T_est_gt * p.T_W_B;
    est.push_back({p.t, SE3(m.quat(), c * m.translation())});
  }
  EvalParams sim3;
  sim3.align = AlignMode::kSim3;
  auto ev = evaluateTrajectory(gt, est, sim3);
  ASSERT_TRUE(ev.ok()) << ev.error();
  EXPECT_NEAR(ev->ate.alignment.scale, 1.0 / c, 1e-9);
  EXPECT_LT(ev->ate.trans_m.max, 1e-9);
  EXPECT_LT(ev->rpe.trans_m.max, 1e-9);  // RPE sees the scale-corrected estimate
  auto rigid = evaluateTrajectory(gt, est, EvalParams{});
  ASSERT_TRUE(rigid.ok());
  EXPECT_GT(rigid->ate.trans_m.rmse, 0.5);
}

TEST(Rpe, ConstantTranslationDriftPerSecond) {
  // gt at 10 Hz, turning; the estimate drifts 0.02 m/s along world y.
  const Trajectory gt = helix(201, 0.1);
  Trajectory est = gt;
  for (auto& p : est)
    p.T_W_B = SE3(p.T_W_B.quat(), p.T_W_B.translation() + Vec3(0, 0.02 * p.t, 0));
  for (AlignMode mode : {AlignMode::kNone, AlignMode::kSE3}) {
    EvalParams params;
    params.align = mode;
    auto ev = evaluateTrajectory(gt, est, params);
    ASSERT_TRUE(ev.ok());
    EXPECT_EQ(ev->rpe.pairs, 191u);  // i = 0..190 have a partner 1 s later
    EXPECT_NEAR(ev->rpe.trans_m.rmse, 0.02, 1e-9);
    EXPECT_NEAR(ev->rpe.trans_m.max, 0.02, 1e-9);
    EXPECT_LT(ev->rpe.rot_deg.max, 1e-6);
  }
  EvalParams frames;
  frames.rpe_delta_frames = 5;
  auto ev = evaluateTrajectory(gt, est, frames);
  ASSERT_TRUE(ev.ok());
  EXPECT_EQ(ev->rpe.pairs, 196u);
  EXPECT_NEAR(ev->rpe.trans_m.rmse, 0.01, 1e-9);
}

TEST(Rpe, ConstantYawDriftPerSecond) {
  Trajectory gt, est;
  const double drift = 0.5 * M_PI / 180.0;  // 0.5 deg/s
  for (int i = 0; i <= 100; ++i) {
    const double t = 0.1 * i;
    const Mat3 R = expSO3(Vec3(0.02 * t, -0.03 * t, 0.3 * t));
    gt.push_back({t, SE3(R, Vec3::Zero())});
    est.push_back({t, SE3(expSO3(Vec3(0, 0, drift * t)) * R, Vec3::Zero())});
  }
  EvalParams none;
  none.align = AlignMode::kNone;
  none.rpe_delta_s = 2.0;
  auto ev = evaluateTrajectory(gt, est, none);
  ASSERT_TRUE(ev.ok());
  EXPECT_EQ(ev->rpe.pairs, 81u);
  EXPECT_NEAR(ev->rpe.rot_deg.rmse, 1.0, 1e-7);  // 0.5 deg/s over 2 s
  EXPECT_NEAR(ev->rpe.rot_deg.max, 1.0, 1e-7);
  EXPECT_LT(ev->rpe.trans_m.max, 1e-12);
}

TEST(Association, OffsetStampsGapsAndEnds) {
  // gt at 200 Hz over [0, 10] s, moving at 1 m/s in x while yawing at constant rate,
  // with a gap [4, 5) s; linear motion makes interpolation exact.
  Trajectory gt;
  for (int k = 0; k <= 2000; ++k) {
    const double t = 0.005 * k;
    if (t >= 4.0 - 1e-9 && t < 5.0 - 1e-9) continue;
    gt.push_back({t, SE3(expSO3(Vec3(0, 0, 0.2 * t)), Vec3(t, 0, 0))});
  }
  Trajectory est;
  est.push_back({-0.05, SE3()});  // too early: unmatched
  est.push_back({-0.01, SE3()});  // before the span, within max_dt: first sample
  for (int m = 0; m < 100; ++m) {
    const double t = 0.0025 + 0.1 * m;  // half-way between gt samples
    est.push_back({t, SE3(expSO3(Vec3(0, 0, 0.2 * t)), Vec3(t, 0, 0))});
  }
  est.push_back({10.05, SE3()});  // after the span by 0.05 s: unmatched
  auto a = associate(gt, est, 0.02);
  ASSERT_TRUE(a.ok()) << a.error();
  // In the gap only 4.0025 (7.5 ms after 3.995) has a gt sample within 20 ms.
  EXPECT_EQ(a->unmatched, 11u);
  EXPECT_EQ(a->matched(), 92u);
  EXPECT_DOUBLE_EQ(a->t[0], -0.01);
  EXPECT_LT(a->gt[0].translation().norm(), 1e-15);
  for (size_t i = 1; i < a->matched(); ++i) {
    EXPECT_NEAR(a->gt[i].translation().x(), a->t[i], 1e-12) << "t=" << a->t[i];
    EXPECT_NEAR(relativeAngle(a->gt[i].quat(), a->est[i].quat()), 0, 1e-9);
  }
  EXPECT_FALSE(associate({}, est, 0.02).ok());
  Trajectory unsorted = gt;
  std::swap(unsorted[3], unsorted[4]);
  EXPECT_FALSE(associate(unsorted, est, 0.02).ok());
}

TEST(Evaluate, NoMatchIsAnErrorNamingTheAgent) {
  const Trajectory gt = helix(50, 0.1);
  const Trajectory est = helix(50, 0.1, 1000.0);
  auto ev = evaluateTrajectory(gt, est, EvalParams{}, "robot7");
  ASSERT_FALSE(ev.ok());
  EXPECT_NE(ev.error().find("robot7"), std::string::npos) << ev.error();
  EXPECT_NE(ev.error().find("max_dt"), std::string::npos) << ev.error();
  EvalParams bad;
  bad.max_dt = -1;
  EXPECT_FALSE(evaluateTrajectory(gt, gt, bad).ok());
}

TEST(MultiAgent, MergedAteSeesAnOffsetAgent) {
  const Trajectory gt_a = helix(300, 0.05);
  Trajectory gt_b;
  for (const auto& p : helix(300, 0.05)) gt_b.push_back({p.t, SE3(p.T_W_B.quat(), p.T_W_B.translation() + Vec3(1, -2, 0.5))});
  const Vec3 d(0.4, 0, 0);  // agent b's map sits 0.4 m off in the merged frame
  Trajectory est_b;
  for (const auto& p : gt_b) est_b.push_back({p.t, SE3(p.T_W_B.quat(), p.T_W_B.translation() + d)});
  const std::vector<AgentTrajectories> agents = {{"a", gt_a, gt_a}, {"b", gt_b, est_b}};

  auto ev = evaluateAgents(agents, EvalParams{});
  ASSERT_TRUE(ev.ok()) << ev.error();
  ASSERT_EQ(ev->agents.size(), 2u);
  EXPECT_LT(ev->agents[0].ate.trans_m.rmse, 1e-9);  // each alone is perfect
  EXPECT_LT(ev->agents[1].ate.trans_m.rmse, 1e-9);
  EXPECT_EQ(ev->matched, 600u);
  // Shifting all by -d/2 is one feasible common transform (rmse |d|/2); the optimum
  // cannot be worse, and no rigid transform can fix an inconsistent map.
  EXPECT_LE(ev->merged_ate.trans_m.rmse, 0.2 + 1e-9);
  EXPECT_GT(ev->merged_ate.trans_m.rmse, 0.05);
  EXPECT_GT(ev->merged_per_agent_m[0].rmse, 0.02);
  EXPECT_GT(ev->merged_per_agent_m[1].rmse, 0.02);

  EvalParams none;
  none.align = AlignMode::kNone;
  auto raw = evaluateAgents(agents, none);
  ASSERT_TRUE(raw.ok());
  EXPECT_NEAR(raw->merged_ate.trans_m.rmse, 0.4 / std::sqrt(2.0), 1e-12);
  EXPECT_NEAR(raw->merged_per_agent_m[1].rmse, 0.4, 1e-12);

  // A consistent merged map (both agents moved by the same transform) scores 0.
  const SE3 T(expSO3(Vec3(0.3, -0.2, 1.0)), Vec3(5, 6, 7));
  std::vector<AgentTrajectories> consistent = agents;
  consistent[1].est = gt_b;
  for (auto& ag : consistent)
    for (auto& p : ag.est) p.T_W_B = T * p.T_W_B;
  auto ok = evaluateAgents(consistent, EvalParams{});
  ASSERT_TRUE(ok.ok());
  EXPECT_LT(ok->merged_ate.trans_m.rmse, 1e-9);
}

TEST(EvalIo, ReadsEurocCsvAndDetectsFormats) {
  const std::string dir = ::testing::TempDir();
  const std::string csv = dir + "/gt.csv";
  std::ofstream(csv) << "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], "
                        "q_RS_x [], q_RS_y [], q_RS_z [], v...\n"
                        "1403715273262142976,1,2,3,1,0,0,0,0.1,0.2\n"
                        "1403715273312143104,1.5,2,3,0,0,0,1,0.1,0.2\n";
  auto f = detectTrajectoryFormat(csv);
  ASSERT_TRUE(f.ok());
  EXPECT_EQ(*f, TrajectoryFormat::kEurocCsv);
  auto t = readTrajectoryForEval(csv);
  ASSERT_TRUE(t.ok()) << t.error();
  ASSERT_EQ(t->size(), 2u);
  EXPECT_NEAR((*t)[1].t - (*t)[0].t, 0.050000128, 1e-6);  // double resolution at 1.4e9 s
  EXPECT_NEAR((*t)[0].t, 1403715273.262142976, 1e-6);
  EXPECT_NEAR(rotationAngle((*t)[1].T_W_B.rotation()), M_PI, 1e-9);  // qz = 1

  const std::string tum = dir + "/est.txt";
  std::ofstream(tum) << "# t x y z qx qy qz qw\n1403715273.26 1 2 3 0 0 0 1\n";
  EXPECT_EQ(*detectTrajectoryFormat(tum), TrajectoryFormat::kTum);

  const std::string bad = dir + "/bad.csv";
  std::ofstream(bad) << "1403715273262142976,1,2,3,1,0,0,0\n1403715273312143104,1,2,x\n";
  auto b = readTrajectoryForEval(bad);
  ASSERT_FALSE(b.ok());
  EXPECT_NE(b.error().find(bad + ":2"), std::string::npos) << b.error();
  EXPECT_FALSE(readTrajectoryForEval(dir + "/does_not_exist.txt").ok());
  EXPECT_FALSE(readTrajectoryForEval(dir).ok());  // a folder without mav0/

  // A real EuRoC folder resolves to its ground truth (42 poses at 20 Hz).
  auto real = readTrajectoryForEval(std::string(HERMES_DATA_DIR) + "/euroc_V1_01_micro");
  ASSERT_TRUE(real.ok()) << real.error();
  EXPECT_EQ(real->size(), 42u);
}

TEST(MultiAgent, PartialEvaluationSkipsAnAgentWithoutGroundTruth) {
  const Trajectory gt = helix(100, 0.1);
  const Trajectory far = helix(100, 0.1, 500.0);
  const std::vector<AgentTrajectories> agents = {{"ok", gt, gt}, {"lost", gt, far}};
  EXPECT_FALSE(evaluateAgents(agents, EvalParams{}).ok());
  auto ev = evaluateAgents(agents, EvalParams{}, /*allow_partial=*/true);
  ASSERT_TRUE(ev.ok()) << ev.error();
  ASSERT_EQ(ev->agents.size(), 1u);
  ASSERT_EQ(ev->failed.size(), 1u);
  EXPECT_EQ(ev->failed[0].name, "lost");
  EXPECT_EQ(ev->matched, 100u);
  EXPECT_LT(ev->merged_ate.trans_m.rmse, 1e-9);
  EXPECT_FALSE(evaluateAgents({{"lost", gt, far}}, EvalParams{}, true).ok());
}

TEST(EvalIo, CameraEstimatesMapToTheBodyFrame) {
  auto T_B_C = readEurocSensorExtrinsic(std::string(HERMES_DATA_DIR) +
                                        "/euroc_V1_01_micro/mav0/cam0/sensor.yaml");
  ASSERT_TRUE(T_B_C.ok()) << T_B_C.error();
  EXPECT_NEAR(T_B_C->translation().x(), -0.0216401454975, 1e-12);
  EXPECT_NEAR(T_B_C->translation().y(), -0.064676986768, 1e-12);
  // The camera trajectory differs from the body one by the lever arm; mapped back it
  // evaluates to zero.
  const Trajectory gt = helix(200, 0.05);
  const Trajectory cam = transformTrajectory(gt, *T_B_C);
  auto raw = evaluateTrajectory(gt, cam, EvalParams{});
  ASSERT_TRUE(raw.ok());
  EXPECT_GT(raw->ate.trans_m.rmse, 0.01);
  auto body = evaluateTrajectory(gt, transformTrajectory(cam, T_B_C->inverse()), EvalParams{});
  ASSERT_TRUE(body.ok());
  EXPECT_LT(body->ate.trans_m.rmse, 1e-9);

  const std::string bad = ::testing::TempDir() + "/bad_sensor.yaml";
  std::ofstream(bad) << "%YAML:1.0\nT_BS:\n  data: [1, 0, 0]\n";
  auto b = readEurocSensorExtrinsic(bad);
  ASSERT_FALSE(b.ok());
  EXPECT_NE(b.error().find("16 numbers"), std::string::npos) << b.error();
}
