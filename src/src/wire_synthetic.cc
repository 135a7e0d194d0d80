#include "hermes/core/wire_synthetic.h"

#include <algorithm>
#include <random>
#include <unordered_set>

namespace hermes {
namespace {

Descriptor randomDescriptor(std::mt19937_64& rng) {
  Descriptor d;
  for (std::size_t i = 0; i < d.size(); i += 8) {
    const std::uint64_t v = rng();
    for (int b = 0; b < 8; ++b) d[i + b] = static_cast<std::uint8_t>(v >> (8 * b));
  }
  return d;
}

/// Flips a few bits, as a keypoint's descriptor differs from its landmark's.
Descriptor perturb(Descriptor d, std::mt19937_64& rng) {
  const int flips = static_cast<int>(rng() % 12);
  for (int i = 0; i < flips; ++i) {
    const unsigned bit = static_cast<unsigned>(rng() % 256);
    d[bit / 8] = static_cast<std::uint8_t>(d[bit / 8] ^ (1u << (bit % 8)));
  }
  return d;
}

std::uint8_t randomOctave(std::mt19937_64& rng) {
  std::uint8_t o = 0;
  while (o < 7 && (rng() % 100) < 40) ++o;  // geometric, like an ORB pyramid
  return o;
}

std::vector<std::uint64_t> makeIds(int n, std::uint64_t first, bool random,
                                   std::mt19937_64& rng) {
  std::vector<std::uint64_t> ids;
  std::unordered_set<std::uint64_t> used;
  std::uint64_t next = first;
  while (static_cast<int>(ids.size()) < n) {
    std::uint64_t id = random ? rng() : next;
    next += 1 + (rng() % 4 == 0 ? rng() % 5 : 0);  // mostly consecutive, some gaps
    if (id == kInvalidId || !used.insert(id).second) continue;
    ids.push_back(id);
  }
  return ids;
}

}  // namespace

Submap makeSyntheticSubmap(const SyntheticSubmapOptions& o) {
  std::mt19937_64 rng(o.seed * 0x9E3779B97F4A7C15ULL + 17);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::normal_distribution<double> noise(0.0, 1.0);

  Submap s;
  s.header.agent = uuidFromSeed(o.seed);
  s.header.session = static_cast<std::uint32_t>(rng() % 4);
  s.header.seq = rng() % 1000;
  s.header.t_start = 100.0 + 10.0 * unit(rng);
  for (int c = 0; c < std::max(1, o.cameras); ++c)
    s.cameras.push_back(PinholeIntrinsics{458.654 + c, 457.296, 367.215, 248.375, 752, 480});

  const double dt = 0.4;
  const auto kf_ids = makeIds(o.keyframes, 1000 + rng() % 1000, o.random_ids, rng);
  for (int i = 0; i < o.keyframes; ++i) {
    Keyframe kf;
    kf.id = kf_ids[i];
    kf.stamp = s.header.t_start + dt * i + 0.01 * unit(rng);
    const Vec3 t(0.25 * i + 0.02 * noise(rng), 0.03 * noise(rng), 0.05 * i);
    kf.T_A_C = SE3(expSO3(Vec3(0.02 * noise(rng), 0.03 * i + 0.02 * noise(rng), 0.01 * noise(rng))), t);
    kf.camera_id = static_cast<std::uint32_t>(rng() % s.cameras.size());
    s.keyframes.push_back(std::move(kf));
  }
  s.header.t_end = s.keyframes.empty() ? s.header.t_start : s.keyframes.back().stamp;

  const int cap = std::max(0, o.keypoints_per_keyframe);
  const int matched_cap = static_cast<int>(o.matched_fraction * cap);
  const auto lm_ids = makeIds(o.landmarks, 50000 + rng() % 100000, o.random_ids, rng);
  for (int j = 0; j < o.landmarks; ++j) {
    Landmark lm;
    lm.id = lm_ids[j];
    lm.p_A = Vec3(-4.0 + (8.0 + 0.25 * o.keyframes) * unit(rng), -3.0 + 6.0 * unit(rng),
                  2.0 + 8.0 * unit(rng));
    lm.descriptor = randomDescriptor(rng);
    bool first = true;
    for (Keyframe& kf : s.keyframes) {
      if (static_cast<int>(kf.keypoints.size()) >= matched_cap) continue;
      const Vec3 p_C = kf.T_A_C.inverse() * lm.p_A;
      if (p_C.z() < 0.1) continue;
      const PinholeIntrinsics& cam = s.cameras[kf.camera_id];
      const Vec2 uv = cam.project(p_C) + 0.5 * Vec2(noise(rng), noise(rng));
      if (!cam.inImage(uv)) continue;
      if (!first && unit(rng) > o.observe_probability) continue;
      first = false;
      Keypoint kp;
      kp.u = static_cast<float>(uv.x());
      kp.v = static_cast<float>(uv.y());
      kp.octave = randomOctave(rng);
      kp.depth = unit(rng) < 0.8 ? static_cast<float>(p_C.z() * (1 + 0.01 * noise(rng))) : 0.f;
      lm.observations.push_back({kf.id, static_cast<std::uint32_t>(kf.keypoints.size())});
      kf.keypoints.push_back(kp);
      kf.descriptors.push_back(perturb(lm.descriptor, rng));
      kf.keypoint_landmark.push_back(lm.id);
    }
    s.landmarks.push_back(std::move(lm));
  }
  for (Keyframe& kf : s.keyframes) {  // unmatched keypoints fill each keyframe up
    const PinholeIntrinsics& cam = s.cameras[kf.camera_id];
    while (static_cast<int>(kf.keypoints.size()) < cap) {
      Keypoint kp;
      kp.u = static_cast<float>(cam.width * unit(rng));
      kp.v = static_cast<float>(cam.height * unit(rng));
      kp.octave = randomOctave(rng);
      kp.depth = unit(rng) < 0.6 ? static_cast<float>(1.0 + 9.0 * unit(rng)) : 0.f;
      kf.keypoints.push_back(kp);
      kf.descriptors.push_back(randomDescriptor(rng));
      kf.keypoint_landmark.push_back(kInvalidId);
    }
  }
  // Matched and unmatched keypoints interleave in a real keyframe: shuffle.
  std::vector<std::vector<std::uint32_t>> new_index(s.keyframes.size());
  for (std::size_t i = 0; i < s.keyframes.size(); ++i) {
    Keyframe& kf = s.keyframes[i];
    std::vector<std::uint32_t> order(kf.keypoints.size());
    for (std::size_t k = 0; k < order.size(); ++k) order[k] = static_cast<std::uint32_t>(k);
    std::shuffle(order.begin(), order.end(), rng);
    Keyframe shuffled = kf;
    new_index[i].resize(order.size());
    for (std::size_t k = 0; k < order.size(); ++k) {
      shuffled.keypoints[k] = kf.keypoints[order[k]];
      shuffled.descriptors[k] = kf.descriptors[order[k]];
      shuffled.keypoint_landmark[k] = kf.keypoint_landmark[order[k]];
      new_index[i][order[k]] = static_cast<std::uint32_t>(k);
    }
    kf = std::move(shuffled);
  }
  for (Landmark& lm : s.landmarks)
    for (Observation& ob : lm.observations) {
      std::size_t i = 0;
      while (s.keyframes[i].id != ob.keyframe) ++i;
      ob.keypoint = new_index[i][ob.keypoint];
    }
  for (std::size_t i = 1; i < s.keyframes.size(); ++i) {
    OdometryEdge e;
    e.from = s.keyframes[i - 1].id;
    e.to = s.keyframes[i].id;
    e.T_from_to = s.keyframes[i - 1].T_A_C.inverse() * s.keyframes[i].T_A_C;
    Mat6 A;
    for (int k = 0; k < 36; ++k) A(k / 6, k % 6) = noise(rng);
    e.information = 1e4 * Mat6::Identity() + 50.0 * A * A.transpose();
    s.odometry.push_back(e);
  }
  return s;
}

}  // namespace hermes
