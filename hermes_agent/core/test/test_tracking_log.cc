// Tracking recordings (tracking_log.h): a lossless round trip of everything the
// window step takes from the tracker, and clear errors (never a crash) for a
// truncated or damaged file and for a key that does not match.
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <iterator>
#include <random>

#include "hermes/agent/tracking_log.h"
#include "hermes/agent/tracking_front.h"

using namespace hermes;
using namespace hermes::agent;

namespace {

SE3 randomPose(std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  return SE3(Quat(n(rng), n(rng), n(rng), n(rng)), Vec3(n(rng), n(rng), n(rng)) * 3.1);
}

/// A window with awkward values: non-round doubles, keypoints without a
/// landmark, odometry information that is not a float.
Submap randomWindow(std::mt19937& rng, std::uint64_t seq) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Submap s;
  s.header.agent = agentUuid("MH_01");
  s.header.session = 3;
  s.header.seq = seq;
  s.header.t_start = 1403636579.763555527 + u(rng);
  s.header.t_end = s.header.t_start + 5.000000001;
  s.cameras.push_back(PinholeIntrinsics{458.654 + u(rng), 457.296, 367.215, 248.375, 752, 480});
  for (int k = 0; k < 3; ++k) {
    Keyframe kf;
    kf.id = 10 * seq + static_cast<KeyframeId>(k);
    kf.stamp = s.header.t_start + 0.1 * k + u(rng) * 1e-7;
    kf.T_A_C = randomPose(rng);
    kf.lost_before = k == 1;
    for (int p = 0; p < 7; ++p) {
      kf.keypoints.push_back({float(u(rng) * 700), float(u(rng) * 400), std::uint8_t(p % 4),
                              p % 3 ? float(u(rng) * 9) : 0.f});
      Descriptor d;
      for (auto& b : d) b = static_cast<std::uint8_t>(rng());
      kf.descriptors.push_back(d);
      kf.keypoint_landmark.push_back(p % 2 ? kInvalidId : static_cast<LandmarkId>(100 + p));
    }
    s.keyframes.push_back(kf);
  }
  for (int l = 0; l < 4; ++l) {
    Landmark lm;
    lm.id = static_cast<LandmarkId>(100 + 2 * l);
    lm.p_A = Vec3(u(rng), u(rng), u(rng)) * 17.3;
    for (auto& b : lm.descriptor) b = static_cast<std::uint8_t>(rng());
    lm.observations.push_back({s.keyframes[0].id, static_cast<std::uint32_t>(2 * l)});
    s.landmarks.push_back(lm);
  }
  OdometryEdge e;
  e.from = s.keyframes[0].id;
  e.to = s.keyframes[1].id;
  e.T_from_to = randomPose(rng);
  for (int k = 0; k < 36; ++k) e.information(k / 6, k % 6) = u(rng) * 1e4 / 3.0;
  s.odometry.push_back(e);
  return s;
}

std::vector<std::uint8_t> lossless(const Submap& s) {
  std::vector<std::uint8_t> b;
  encodeSubmapLossless(s, &b);
  return b;
}

TrackingKey sampleKey() {
  TrackingKey key;
  key.add("agent", "MH_01");
  key.add("frames", "300");
  key.add("tracker_params", textHash("orb:\n  n_features: 1000\n"));
  return key;
}

struct Recorded {
  std::string path;
  std::vector<TrackingStep> steps;
  TrackingSummary summary;
  std::vector<std::uint8_t> bytes;
};

Recorded writeSample(const std::string& name) {
  Recorded r;
  r.path = ::testing::TempDir() + "/" + name + ".htrk";
  std::mt19937 rng(7);
  for (int i = 0; i < 6; ++i) {
    TrackingStep step;
    step.stamp = 100.05 * (i + 1) + 1e-9 * i;
    step.status = i == 0 ? TrackingStatus::kNotInitialised : (i == 3 ? TrackingStatus::kLost : TrackingStatus::kOk);
    if (step.status == TrackingStatus::kOk) step.T_W_B = randomPose(rng);
    step.motion.valid = i > 1;
    step.motion.T_A_C = randomPose(rng);
    step.motion.T_Cprev_Ccurr = randomPose(rng);
    step.motion.dt_s = 0.05000000001 * i;
    step.motion.health = {i, 1, 2, 33};
    if (i % 2 == 1) step.window = randomWindow(rng, static_cast<std::uint64_t>(i));
    r.steps.push_back(step);
  }
  TrackingStep flush;
  flush.flush = true;
  flush.stamp = 700.000001;
  flush.window = randomWindow(rng, 9);
  r.steps.push_back(flush);
  r.summary = {6, 2, 14, 2034, {6, 1, 3, 40}};
  auto w = TrackingLogWriter::create(r.path, sampleKey());
  EXPECT_TRUE(w.ok()) << w.error();
  for (const TrackingStep& s : r.steps) EXPECT_TRUE((*w)->append(s));
  EXPECT_TRUE((*w)->close(r.summary));
  std::ifstream in(r.path, std::ios::binary);
  r.bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  return r;
}

bool samePose(const SE3& a, const SE3& b) {
  return a.quat().coeffs() == b.quat().coeffs() && a.translation() == b.translation();
}

}  // namespace

TEST(TrackingLog, RoundTripIsLossless) {
  const Recorded r = writeSample("tracking_roundtrip");
  auto log = readTrackingLog(r.path);
  ASSERT_TRUE(log.ok()) << log.error();
  EXPECT_TRUE(log->key.matches(sampleKey()));
  ASSERT_EQ(log->steps.size(), r.steps.size());
  for (std::size_t i = 0; i < r.steps.size(); ++i) {
    const TrackingStep& a = r.steps[i];
    const TrackingStep& b = log->steps[i];
    EXPECT_EQ(a.flush, b.flush);
    EXPECT_EQ(a.stamp, b.stamp);  // bit for bit, no tolerance
    EXPECT_EQ(a.status, b.status);
    EXPECT_TRUE(samePose(a.T_W_B, b.T_W_B)) << i;
    EXPECT_EQ(a.motion.valid, b.motion.valid);
    EXPECT_TRUE(samePose(a.motion.T_A_C, b.motion.T_A_C));
    EXPECT_TRUE(samePose(a.motion.T_Cprev_Ccurr, b.motion.T_Cprev_Ccurr));
    EXPECT_EQ(a.motion.dt_s, b.motion.dt_s);
    EXPECT_EQ(a.motion.health.min_tracked, b.motion.health.min_tracked);
    ASSERT_EQ(a.window.has_value(), b.window.has_value()) << i;
    if (!a.window) continue;
    EXPECT_EQ(lossless(*a.window), lossless(*b.window)) << i;
    EXPECT_TRUE(samePose(a.window->keyframes[2].T_A_C, b.window->keyframes[2].T_A_C));
    EXPECT_EQ(a.window->landmarks[1].p_A, b.window->landmarks[1].p_A);
    EXPECT_EQ(a.window->odometry[0].information, b.window->odometry[0].information);
    EXPECT_EQ(b.window->keyframes[0].keypoint_landmark[1], kInvalidId);
  }
  EXPECT_EQ(log->summary.landmarks, 2034);
  EXPECT_EQ(log->summary.total_health.weak, 3);
}

TEST(TrackingLog, TruncatedOrFlippedFilesAreRefusedWithoutCrashing) {
  const Recorded r = writeSample("tracking_fuzz");
  ASSERT_TRUE(decodeTrackingLog(r.bytes, "sample").ok());
  for (std::size_t n = 0; n < r.bytes.size(); n += (n < 400 ? 1 : 37)) {
    const std::vector<std::uint8_t> cut(r.bytes.begin(), r.bytes.begin() + static_cast<std::ptrdiff_t>(n));
    auto log = decodeTrackingLog(cut, "sample");
    ASSERT_FALSE(log.ok()) << "truncated to " << n << " bytes";
    EXPECT_NE(log.error().find("sample"), std::string::npos) << log.error();
  }
  auto cut = decodeTrackingLog({r.bytes.begin(), r.bytes.end() - 30}, "sample");
  ASSERT_FALSE(cut.ok());
  EXPECT_NE(cut.error().find("truncated"), std::string::npos) << cut.error();
  std::mt19937 rng(3);
  for (std::size_t i = 0; i < r.bytes.size(); i += (i < 200 ? 1 : 13)) {
    std::vector<std::uint8_t> bad = r.bytes;
    bad[i] ^= static_cast<std::uint8_t>(1u << (rng() % 8));
    EXPECT_FALSE(decodeTrackingLog(bad, "sample").ok()) << "flipped byte " << i;
  }
  // Random garbage after a valid magic and version: refused, no crash.
  for (int k = 0; k < 200; ++k) {
    std::vector<std::uint8_t> junk(r.bytes.begin(), r.bytes.begin() + 6);
    for (int j = 0; j < 64 + k; ++j) junk.push_back(static_cast<std::uint8_t>(rng()));
    EXPECT_FALSE(decodeTrackingLog(junk, "junk").ok());
  }
  EXPECT_FALSE(readTrackingLog(::testing::TempDir() + "/no_such_recording.htrk").ok());
}

TEST(TrackingLog, KeyMismatchNamesTheField) {
  TrackingKey recorded = sampleKey();
  TrackingKey other = sampleKey();
  other.fields[1].second = "301";
  Status s = recorded.matches(other);
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().find("'frames' differs"), std::string::npos) << s.error();
  EXPECT_NE(s.error().find("300"), std::string::npos) << s.error();
  TrackingKey more = sampleKey();
  more.add("corruption", "none");
  s = recorded.matches(more);
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().find("corruption"), std::string::npos) << s.error();
}

TEST(TrackingLog, ReplayFrontHandsOutTheRecordedStepsInOrder) {
  const Recorded r = writeSample("tracking_replay_source");
  auto log = readTrackingLog(r.path);
  ASSERT_TRUE(log.ok()) << log.error();
  ReplayFront replay(std::move(*log));
  replay.setAgent(agentUuid("other"), 5);
  EXPECT_FALSE(replay.next(false, r.steps[0].stamp + 1).ok());  // out of step
  for (std::size_t i = 0; i + 1 < r.steps.size(); ++i) {
    auto step = replay.next(false, r.steps[i].stamp);
    ASSERT_TRUE(step.ok()) << step.error();
    auto window = replay.takeWindowIfDue(r.steps[i].stamp);
    ASSERT_EQ(window.has_value(), r.steps[i].window.has_value());
    if (window) {
      EXPECT_EQ(window->header.session, 5u);
      EXPECT_EQ(window->header.agent, agentUuid("other"));
      EXPECT_EQ(window->header.seq, r.steps[i].window->header.seq);
      EXPECT_FALSE(replay.takeWindowIfDue(r.steps[i].stamp).has_value());  // once
    }
    EXPECT_EQ(replay.motionHint().dt_s, r.steps[i].motion.dt_s);
  }
  EXPECT_FALSE(replay.done());
  EXPECT_FALSE(replay.next(false, 1e9).ok());  // the flush comes next
  ASSERT_TRUE(replay.next(true, 0).ok());
  EXPECT_TRUE(replay.takeWindowIfDue(0).has_value());
  EXPECT_TRUE(replay.done());
  EXPECT_FALSE(replay.next(true, 0).ok());
}
