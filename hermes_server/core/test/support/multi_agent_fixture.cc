#include "multi_agent_fixture.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <random>

#include "hermes/core/wire_format.h"

namespace hermes {
namespace server {
namespace fixture {
namespace {

SE3 randomSmall(std::mt19937_64& rng, double sigma_m, double sigma_rad) {
  std::normal_distribution<double> n(0.0, 1.0);
  Vec6 xi;
  for (int i = 0; i < 3; ++i) xi[i] = sigma_m * n(rng);
  for (int i = 3; i < 6; ++i) xi[i] = sigma_rad * n(rng);
  return SE3::exp(xi);
}

struct AgentTimeline {
  std::vector<double> t;
  std::vector<SE3> T_W_C;
};

}  // namespace

Expected<Fixture> makeFixture(const std::vector<AgentSpec>& specs, const Options& o) {
  Fixture fx;
  fx.camera = PinholeIntrinsics{458.0, 457.0, 367.0, 248.0, 752, 480};
  Mat3 R_B_C;
  R_B_C << 0, -1, 0, 1, 0, 0, 0, 0, 1;  // EuRoC cam0 looks along body z
  fx.T_B_C = SE3(R_B_C, Vec3(-0.02, -0.06, 0.01));
  std::mt19937_64 rng(o.seed);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  std::normal_distribution<double> gauss(0.0, 1.0);

  std::vector<AgentTimeline> timelines;
  for (const AgentSpec& spec : specs) {
    auto gt = readTumTrajectory(spec.gt_file);
    if (!gt) return Error{"fixture: " + gt.error()};
    if (gt->empty()) return Error{"fixture: empty ground truth " + spec.gt_file};
    AgentTimeline tl;
    const double t0 = gt->front().t;
    for (double t = t0 + spec.from_s; t <= t0 + spec.to_s + 1e-9; t += o.keyframe_period_s) {
      SE3 T_W_B;
      if (!interpolatePose(*gt, t, &T_W_B)) continue;
      tl.t.push_back(t);
      tl.T_W_C.push_back(T_W_B * fx.T_B_C);
    }
    if (tl.t.size() < 4) return Error{"fixture: span too short in " + spec.gt_file};
    timelines.push_back(std::move(tl));
  }

  // Shared hall landmarks, seeded in front of every keyframe of every agent.
  std::vector<Vec3> points;
  std::vector<Descriptor> descriptors;
  for (const AgentTimeline& tl : timelines)
    for (const SE3& T_W_C : tl.T_W_C)
      for (int i = 0; i < o.landmarks_per_keyframe; ++i) {
        const Vec2 uv(uni(rng) * fx.camera.width, uni(rng) * fx.camera.height);
        const double depth = 2.0 + 6.0 * uni(rng);
        points.push_back(T_W_C * (fx.camera.bearing(uv) * depth / fx.camera.bearing(uv).z()));
        Descriptor d;
        for (auto& b : d) b = static_cast<std::uint8_t>(rng() & 0xff);
        descriptors.push_back(d);
      }
  fx.landmarks = points.size();

  for (std::size_t a = 0; a < specs.size(); ++a) {
    const AgentTimeline& tl = timelines[a];
    Agent agent;
    agent.uuid = uuidFromSeed(1000 + a);
    std::uint32_t session = 0;
    auto randomFrame = [&]() {
      const double yaw = (uni(rng) * 2 - 1) * M_PI;
      return SE3(Mat3(Eigen::AngleAxisd(yaw, Vec3::UnitZ())),
                 Vec3(4 * gauss(rng), 4 * gauss(rng), 0.5 * gauss(rng)));
    };
    SE3 T_W_A = randomFrame();
    SE3 T_A_C_prev;
    std::vector<Keyframe> kfs;  // of the current session
    KeyframeId next_id = 0;
    std::uint64_t seq = 0;
    double window_start = tl.t.front();
    std::vector<SE3> est;
    auto flush = [&]() -> Status {
      if (kfs.empty()) return Status::Ok();
      Submap s;
      s.header.agent = agent.uuid;
      s.header.session = session;
      s.header.seq = seq++;
      s.header.t_start = kfs.front().stamp;
      s.header.t_end = kfs.back().stamp;
      s.cameras.push_back(fx.camera);
      std::map<LandmarkId, Landmark> lms;
      for (const Keyframe& kf : kfs)
        for (std::uint32_t k = 0; k < kf.keypoints.size(); ++k) {
          const LandmarkId id = kf.keypoint_landmark[k];
          Landmark& l = lms[id];
          if (l.id == kInvalidId) {
            l.id = id;
            const Vec3 noise(gauss(rng), gauss(rng), gauss(rng));
            l.p_A = T_W_A.inverse() * points[id] + 0.01 * noise;
            l.descriptor = descriptors[id];
          }
          l.observations.push_back({kf.id, k});
        }
      for (auto& [id, l] : lms) s.landmarks.push_back(std::move(l));
      for (std::size_t i = 0; i + 1 < kfs.size(); ++i) {
        OdometryEdge e;
        e.from = kfs[i].id;
        e.to = kfs[i + 1].id;
        e.T_from_to = kfs[i].T_A_C.inverse() * kfs[i + 1].T_A_C;
        e.information = Mat6::Zero();
        e.information.diagonal().head<3>().setConstant(1.0 / (o.drift_m * o.drift_m));
        e.information.diagonal().tail<3>().setConstant(1.0 / (o.drift_rad * o.drift_rad));
        s.odometry.push_back(e);
      }
      s.keyframes = std::move(kfs);
      kfs.clear();
      if (std::string v = s.validate(); !v.empty()) return Error{"fixture: invalid submap: " + v};
      auto frame = encodeSubmap(s);
      if (!frame) return Error{"fixture: " + frame.error()};
      agent.frames.push_back(std::move(*frame));
      agent.submaps.push_back(std::move(s));
      return Status::Ok();
    };
    bool reset_done = false;
    for (std::size_t k = 0; k < tl.t.size(); ++k) {
      const double t = tl.t[k];
      const bool reset = specs[a].reset_at_s >= 0 && !reset_done &&
                         t >= tl.t.front() + specs[a].reset_at_s;
      if (reset || t - window_start >= o.submap_s - 1e-9) {
        if (Status s = flush(); !s) return Error{s.error()};
        window_start = t;
      }
      SE3 T_A_C;
      if (reset) {
        reset_done = true;
        ++session;
        seq = 0;
        next_id = 0;
        T_W_A = randomFrame();
        T_A_C = T_W_A.inverse() * tl.T_W_C[k];
      } else if (k == 0) {
        T_A_C = T_W_A.inverse() * tl.T_W_C[k];
      } else {
        T_A_C = T_A_C_prev * (tl.T_W_C[k - 1].inverse() * tl.T_W_C[k]) *
                randomSmall(rng, o.drift_m, o.drift_rad);
      }
      T_A_C_prev = T_A_C;
      Keyframe kf;
      kf.id = next_id++;
      kf.stamp = t;
      kf.T_A_C = T_A_C;
      const SE3 T_C_W = tl.T_W_C[k].inverse();
      std::vector<std::pair<LandmarkId, Vec2>> visible;
      for (std::size_t i = 0; i < points.size(); ++i) {
        const Vec3 p = T_C_W * points[i];
        if (p.z() < 0.3) continue;
        const Vec2 uv = fx.camera.project(p);
        if (fx.camera.inImage(uv, 2.0)) visible.push_back({i, uv});
      }
      std::shuffle(visible.begin(), visible.end(), rng);
      if (static_cast<int>(visible.size()) > o.keypoints) visible.resize(o.keypoints);
      for (const auto& [id, uv] : visible) {
        Keypoint kp;
        kp.u = static_cast<float>(uv.x() + o.pixel_noise * gauss(rng));
        kp.v = static_cast<float>(uv.y() + o.pixel_noise * gauss(rng));
        kf.keypoints.push_back(kp);
        Descriptor d = descriptors[id];
        for (int f = 0; f < o.bit_flips; ++f) {
          const int bit = static_cast<int>(rng() % 256);
          d[bit / 8] ^= static_cast<std::uint8_t>(1u << (bit % 8));
        }
        kf.descriptors.push_back(d);
        kf.keypoint_landmark.push_back(id);
      }
      kfs.push_back(std::move(kf));
      SE3 T_W_B = tl.T_W_C[k] * fx.T_B_C.inverse();
      agent.gt_body.push_back({t, T_W_B});
      ++agent.keyframes;
    }
    if (Status s = flush(); !s) return Error{s.error()};
    fx.agents.push_back(std::move(agent));
  }
  return fx;
}

std::vector<const std::vector<std::uint8_t>*> roundRobin(const Fixture& fx) {
  std::vector<const std::vector<std::uint8_t>*> out;
  std::size_t rounds = 0;
  for (const Agent& a : fx.agents) rounds = std::max(rounds, a.frames.size());
  for (std::size_t r = 0; r < rounds; ++r)
    for (const Agent& a : fx.agents)
      if (r < a.frames.size()) out.push_back(&a.frames[r]);
  return out;
}

Expected<Fixture> hallPair(double seconds, int keypoints) {
  const std::string gt = std::string(HERMES_TRAJECTORY_DIR) + "/";
  Options options;
  options.keypoints = keypoints;
  return makeFixture({{gt + "MH_01_easy.txt", 0.0, seconds, -1}, {gt + "MH_02_easy.txt", 0.0, seconds, -1}},
                     options);
}

const Fixture& hallTrio() {
  static const Fixture fx = [] {
    const std::string gt = std::string(HERMES_TRAJECTORY_DIR) + "/";
    auto f = makeFixture({{gt + "MH_01_easy.txt", 0.0, 15.0, -1},
                          {gt + "MH_02_easy.txt", 0.0, 16.0, 8.0},  // a second session
                          {gt + "MH_03_medium.txt", 0.0, 15.0, -1}},
                         Options{});
    if (!f) {  // every test on the hall needs it: stop with the reason
      std::fprintf(stderr, "fixture::hallTrio: %s\n", f.error().c_str());
      std::abort();
    }
    return std::move(*f);
  }();
  return fx;
}

}  // namespace fixture
}  // namespace server
}  // namespace hermes
