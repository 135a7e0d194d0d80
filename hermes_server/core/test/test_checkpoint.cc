// Server checkpoints (DESIGN.md §9): the state round-trips exactly, a restored
// server merges the rest as the original would, a crash between checkpoints
// loses nothing (journal) and applies nothing twice, damaged / truncated /
// other-version checkpoints are refused with the previous one used, and the
// decoders survive fuzzed input.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <functional>
#include <filesystem>
#include <fstream>
#include <random>

#include "hermes/core/crc32.h"
#include "hermes/server/server.h"
#include "support/multi_agent_fixture.h"

namespace hermes {
namespace server {
namespace {

namespace fs = std::filesystem;

const fixture::Fixture& hall() { return fixture::hallTrio(); }

/// Frames in sending order (round robin over agents), with their times.
std::vector<std::pair<double, const std::vector<std::uint8_t>*>> schedule() {
  std::vector<std::pair<double, const std::vector<std::uint8_t>*>> out;
  std::size_t rounds = 0;
  for (const auto& a : hall().agents) rounds = std::max(rounds, a.frames.size());
  double now = 0;
  for (std::size_t r = 0; r < rounds; ++r)
    for (const auto& a : hall().agents)
      if (r < a.frames.size()) out.emplace_back(now += 1.0, &a.frames[r]);
  return out;
}

std::string freshDir(const std::string& tag) {
  const std::string dir = ::testing::TempDir() + "/hermes_ckpt_" + tag;
  fs::remove_all(dir);
  return dir;
}

/// In memory: one vocabulary for all (the fuzz test makes hundreds).
std::unique_ptr<Server> makeServer() {
  static const auto vocabulary = loadVocabulary(PlaceRecognitionParams{}, HERMES_SOURCE_DIR);
  EXPECT_TRUE(vocabulary.ok());
  return std::make_unique<Server>(ServerParams{}, *vocabulary);
}

std::unique_ptr<Server> makeServer(const std::string& checkpoint_dir) {
  ServerParams params;
  params.checkpoint.dir = checkpoint_dir;
  auto server = Server::create(params, HERMES_SOURCE_DIR);
  EXPECT_TRUE(server.ok()) << (server ? "" : server.error());
  return server ? std::move(*server) : nullptr;
}

/// Feeds frames [from, to) of the schedule, merging after every second one.
void feed(Server* s, std::size_t from, std::size_t to, bool process = true) {
  const auto frames = schedule();
  for (std::size_t i = from; i < to && i < frames.size(); ++i) {
    const auto& [t, f] = frames[i];
    const ReceiveResult r = s->onFrame(f->data(), f->size(), nullptr, t);
    EXPECT_TRUE(r.acknowledge) << r.reason;
    if (process && i % 2 == 1) s->process(t);
  }
}

void expectPoseNear(const SE3& a, const SE3& b, double tol, const std::string& what) {
  EXPECT_LT((a.translation() - b.translation()).norm(), tol) << what;
  EXPECT_LT(a.quat().angularDistance(b.quat()), tol) << what;
}

/// Field by field; poses to 1e-12 (a quaternion is normalised again on load).
void expectSameMap(const GlobalMap& a, const GlobalMap& b) {
  ASSERT_EQ(a.trajectories.size(), b.trajectories.size());
  for (const auto& [tid, ta] : a.trajectories) {
    ASSERT_TRUE(b.trajectories.count(tid));
    const TrajectoryMap& tb = b.trajectories.at(tid);
    EXPECT_EQ(ta.uuid, tb.uuid);
    EXPECT_EQ(ta.anchored, tb.anchored);
    expectPoseNear(ta.T_W_A, tb.T_W_A, 1e-12, "T_W_A");
    ASSERT_EQ(ta.keyframes.size(), tb.keyframes.size());
    for (const auto& [id, ka] : ta.keyframes) {
      const StoredKeyframe& kb = tb.keyframes.at(id);
      EXPECT_EQ(ka.keyframe.stamp, kb.keyframe.stamp);
      expectPoseNear(ka.keyframe.T_A_C, kb.keyframe.T_A_C, 1e-12, "T_A_C");
      expectPoseNear(ka.T_W_C, kb.T_W_C, 1e-12, "T_W_C");
      EXPECT_EQ(ka.keyframe.lost_before, kb.keyframe.lost_before);
      EXPECT_EQ(ka.camera.fx, kb.camera.fx);
      EXPECT_EQ(ka.camera.width, kb.camera.width);
      ASSERT_EQ(ka.keyframe.keypoints.size(), kb.keyframe.keypoints.size());
      for (std::size_t k = 0; k < ka.keyframe.keypoints.size(); ++k) {
        EXPECT_EQ(ka.keyframe.keypoints[k].u, kb.keyframe.keypoints[k].u);
        EXPECT_EQ(ka.keyframe.keypoints[k].depth, kb.keyframe.keypoints[k].depth);
      }
      EXPECT_EQ(ka.keyframe.descriptors, kb.keyframe.descriptors);
      EXPECT_EQ(ka.keyframe.keypoint_landmark, kb.keyframe.keypoint_landmark);
    }
    ASSERT_EQ(ta.landmarks.size(), tb.landmarks.size());
    for (const auto& [id, la] : ta.landmarks) {
      const StoredLandmark& lb = tb.landmarks.at(id);
      EXPECT_EQ(la.landmark.p_A, lb.landmark.p_A);
      EXPECT_EQ(la.landmark.descriptor, lb.landmark.descriptor);
      EXPECT_EQ(la.anchor, lb.anchor);
      EXPECT_EQ(la.p_anchor, lb.p_anchor);
      ASSERT_EQ(la.landmark.observations.size(), lb.landmark.observations.size());
      for (std::size_t k = 0; k < la.landmark.observations.size(); ++k) {
        EXPECT_EQ(la.landmark.observations[k].keyframe, lb.landmark.observations[k].keyframe);
        EXPECT_EQ(la.landmark.observations[k].keypoint, lb.landmark.observations[k].keypoint);
      }
    }
    ASSERT_EQ(ta.odometry.size(), tb.odometry.size());
    for (const auto& [ids, ea] : ta.odometry) {
      EXPECT_EQ(ea.information, tb.odometry.at(ids).information);
      expectPoseNear(ea.T_from_to, tb.odometry.at(ids).T_from_to, 1e-12, "odometry");
    }
  }
  ASSERT_EQ(a.loops.size(), b.loops.size());
  for (std::size_t i = 0; i < a.loops.size(); ++i) {
    const LoopEdge &la = a.loops[i], &lb = b.loops[i];
    EXPECT_EQ(la.id, lb.id);
    EXPECT_TRUE(la.a == lb.a && la.b == lb.b);
    EXPECT_EQ(la.accepted, lb.accepted);
    EXPECT_EQ(la.inliers, lb.inliers);
    EXPECT_EQ(la.depth_inliers, lb.depth_inliers);
    EXPECT_EQ(la.information, lb.information);
    EXPECT_EQ(la.covariance, lb.covariance);
    expectPoseNear(la.T_a_b, lb.T_a_b, 1e-12, "loop");
  }
}

void expectSameBookkeeping(const Server& a, const Server& b) {
  ASSERT_EQ(a.bookkeeper().robots(), b.bookkeeper().robots());
  for (RobotId r : a.bookkeeper().robots()) {
    const AgentStats *sa = a.bookkeeper().stats(r), *sb = b.bookkeeper().stats(r);
    EXPECT_EQ(sa->uuid, sb->uuid);
    EXPECT_EQ(sa->current_session, sb->current_session);
    EXPECT_EQ(sa->submaps_accepted, sb->submaps_accepted);
    EXPECT_EQ(sa->submaps_applied, sb->submaps_applied);
    EXPECT_EQ(sa->bytes_accepted, sb->bytes_accepted);
    EXPECT_EQ(sa->anchored, sb->anchored);
    EXPECT_EQ(sa->sessions.size(), sb->sessions.size());
  }
  EXPECT_EQ(a.bookkeeper().worldAgent(), b.bookkeeper().worldAgent());
  EXPECT_EQ(a.pending(), b.pending());
  EXPECT_EQ(a.counters().merged, b.counters().merged);
  EXPECT_EQ(a.receiverStats().accepted, b.receiverStats().accepted);
  EXPECT_EQ(a.mapManager().loopsAccepted(), b.mapManager().loopsAccepted());
  EXPECT_EQ(a.timings().count("submap"), b.timings().count("submap"));
}

TEST(Checkpoint, StateRoundTripsAndTheRestoredServerMergesTheRestTheSame) {
  const std::size_t total = schedule().size();
  ASSERT_GT(total, 8u);
  auto original = makeServer();
  ASSERT_TRUE(original);
  feed(original.get(), 0, total / 2);
  feed(original.get(), total / 2, total / 2 + 2, /*process=*/false);  // two left pending
  ASSERT_GT(original->pending(), 0u);
  const std::vector<std::uint8_t> body = original->saveState();
  auto restored = makeServer();
  ASSERT_TRUE(restored);
  ASSERT_TRUE(restored->loadState(body));
  expectSameMap(original->map(), restored->map());
  expectSameBookkeeping(*original, *restored);
  // A server that already holds something refuses to load over it.
  EXPECT_FALSE(restored->loadState(body));

  // Resends of what it accepted are duplicates for the restored server too.
  const auto frames = schedule();
  const auto& f0 = *frames[0].second;
  EXPECT_EQ(restored->onFrame(f0.data(), f0.size(), nullptr, 100.0).verdict, ArrivalVerdict::kDuplicate);
  original->onFrame(f0.data(), f0.size(), nullptr, 100.0);

  feed(original.get(), total / 2 + 2, total);
  feed(restored.get(), total / 2 + 2, total);
  original->process(1e3);
  restored->process(1e3);
  ASSERT_TRUE(original->mapManager().optimize());
  ASSERT_TRUE(restored->mapManager().optimize());
  expectSameBookkeeping(*original, *restored);
  ASSERT_EQ(original->map().loops.size(), restored->map().loops.size());
  double worst = 0;
  for (const auto& [tid, t] : original->map().trajectories)
    for (const auto& [id, kf] : t.keyframes)
      worst = std::max(worst, (kf.T_W_C.translation() -
                               restored->map().trajectories.at(tid).keyframes.at(id).T_W_C.translation())
                                  .norm());
  EXPECT_LT(worst, 1e-6) << "the restored server merged differently";
  EXPECT_EQ(original->mapManager().agentsMerged(), 3);
}

TEST(Checkpoint, CrashBetweenCheckpointsLosesNothingAndAppliesNothingTwice) {
  const std::string dir = freshDir("crash");
  const std::size_t total = schedule().size();
  std::size_t distinct = 0;
  {
    auto server = makeServer(dir);
    ASSERT_TRUE(server);
    feed(server.get(), 0, total / 2);
    server->process(schedule()[total / 2 - 1].first);
    EXPECT_EQ(server->pending(), 0u);
    EXPECT_GT(server->durability().checkpoints, 0u);
    // Accepted and acknowledged, never merged nor checkpointed: only the journal has them.
    feed(server.get(), total / 2, total / 2 + 3, /*process=*/false);
    EXPECT_EQ(server->pending(), 3u);
    distinct = server->receiverStats().accepted;
  }  // destroyed without checkpoint(): a crash
  auto resumed = makeServer(dir);
  ASSERT_TRUE(resumed);
  const ResumeReport& rep = resumed->resumeReport();
  EXPECT_TRUE(rep.resumed);
  EXPECT_FALSE(rep.checkpoint.empty());
  EXPECT_EQ(rep.journal_replayed, 3u);
  EXPECT_TRUE(rep.problems.empty()) << rep.problems.front();
  EXPECT_EQ(resumed->pending(), 3u);
  EXPECT_EQ(resumed->receiverStats().accepted, distinct);
  // The agents resend everything (their acks may have been lost): all duplicates.
  for (std::size_t i = 0; i < total / 2 + 3; ++i) {
    const auto& f = *schedule()[i].second;
    const ReceiveResult r = resumed->onFrame(f.data(), f.size(), nullptr, 200.0);
    EXPECT_EQ(r.verdict, ArrivalVerdict::kDuplicate) << i;
    EXPECT_TRUE(r.acknowledge);
  }
  feed(resumed.get(), total / 2 + 3, total);
  resumed->process(1e3);
  std::uint64_t accepted = 0, applied = 0;
  for (RobotId r : resumed->bookkeeper().robots()) {
    accepted += resumed->bookkeeper().stats(r)->submaps_accepted;
    applied += resumed->bookkeeper().stats(r)->submaps_applied;
  }
  EXPECT_EQ(accepted, total);
  EXPECT_EQ(applied, total);
  EXPECT_EQ(resumed->counters().merged + resumed->counters().merge_errors, total);
  EXPECT_EQ(resumed->counters().merge_errors, 0u) << resumed->counters().last_error;
  EXPECT_EQ(resumed->mapManager().agentsMerged(), 3);
  // After a clean shutdown nothing is left to replay.
  ASSERT_TRUE(resumed->checkpoint(1e3));
  resumed.reset();
  auto again = makeServer(dir);
  ASSERT_TRUE(again);
  EXPECT_EQ(again->resumeReport().journal_replayed, 0u);
  EXPECT_EQ(again->pending(), 0u);
  EXPECT_EQ(again->counters().merged, total);
}

/// The checkpoint files of a directory after a few merges, newest first.
std::vector<std::string> checkpointFiles(const std::string& dir) {
  auto server = makeServer(dir);
  EXPECT_TRUE(server);
  feed(server.get(), 0, 6);
  auto store = CheckpointStore::open(server->params().checkpoint);
  EXPECT_TRUE(store.ok());
  return store->checkpoints();
}

std::vector<std::uint8_t> readBytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::vector<std::uint8_t>((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
}

void writeBytes(const std::string& path, const std::vector<std::uint8_t>& b) {
  std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(b.data()), b.size());
}

/// Damages the newest checkpoint with `damage`, resumes, and expects the
/// previous one to be used and the newest refused for `reason`.
void expectFallback(const std::string& tag,
                    const std::function<void(std::vector<std::uint8_t>*)>& damage,
                    const std::string& reason) {
  SCOPED_TRACE(tag);
  const std::string dir = freshDir(tag);
  const std::vector<std::string> files = checkpointFiles(dir);
  ASSERT_EQ(files.size(), 2u);  // checkpoint_keep
  std::vector<std::uint8_t> bytes = readBytes(files[0]);
  damage(&bytes);
  writeBytes(files[0], bytes);
  auto server = makeServer(dir);
  ASSERT_TRUE(server);
  const ResumeReport& rep = server->resumeReport();
  EXPECT_EQ(rep.checkpoint, files[1]);
  ASSERT_EQ(rep.problems.size(), 1u);
  EXPECT_NE(rep.problems[0].find(files[0]), std::string::npos) << rep.problems[0];
  EXPECT_NE(rep.problems[0].find(reason), std::string::npos) << rep.problems[0];
  EXPECT_TRUE(fs::exists(files[0] + ".refused"));
  EXPECT_EQ(server->durability().refused_files, 1u);
  // Every submap is still there: the journal held what the refused one covered.
  EXPECT_EQ(server->receiverStats().accepted, 6u);
}

void resealCrc(std::vector<std::uint8_t>* b) {
  const std::uint32_t c = crc32(b->data(), b->size() - 4);
  std::memcpy(b->data() + b->size() - 4, &c, 4);
}

TEST(Checkpoint, DamagedTruncatedOrOtherVersionCheckpointsAreRefusedAndThePreviousUsed) {
  expectFallback("flip", [](auto* b) { (*b)[b->size() / 2] ^= 0x04; }, "checksum mismatch");
  expectFallback("truncated", [](auto* b) { b->resize(b->size() * 2 / 3); }, "checksum mismatch");
  expectFallback("empty", [](auto* b) { b->clear(); }, "not a Hermes server checkpoint");
  expectFallback("version", [](auto* b) {
    const std::uint32_t v = kCheckpointVersion + 1;
    std::memcpy(b->data() + 4, &v, 4);
    resealCrc(b);
  }, "format version " + std::to_string(kCheckpointVersion + 1) + ", this build reads version " +
         std::to_string(kCheckpointVersion));
  expectFallback("content", [](auto* b) {  // intact framing, nonsense inside
    for (std::size_t i = 16; i < 48 && i + 4 < b->size(); ++i) (*b)[i] = 0xff;
    resealCrc(b);
  }, "refused: bookkeeper");
}

TEST(Checkpoint, NoUsableCheckpointIsAnErrorNotAnEmptyStart) {
  const std::string dir = freshDir("none");
  const std::vector<std::string> files = checkpointFiles(dir);
  for (const std::string& f : files) writeBytes(f, {1, 2, 3});
  ServerParams params;
  params.checkpoint.dir = dir;
  auto server = Server::create(params, HERMES_SOURCE_DIR);
  ASSERT_FALSE(server.ok());
  for (const std::string& f : files) EXPECT_NE(server.error().find(f), std::string::npos) << server.error();
  EXPECT_NE(server.error().find("no usable checkpoint"), std::string::npos);
}

TEST(Checkpoint, DamagedJournalEntryIsRefusedWithItsName) {
  const std::string dir = freshDir("journal");
  {
    auto server = makeServer(dir);
    ASSERT_TRUE(server);
    feed(server.get(), 0, 2, /*process=*/false);
  }
  std::vector<std::string> entries;
  for (const auto& e : fs::directory_iterator(dir + "/queue")) entries.push_back(e.path().string());
  ASSERT_EQ(entries.size(), 2u);
  std::vector<std::uint8_t> b = readBytes(entries[0]);
  b[b.size() - 10] ^= 1;
  writeBytes(entries[0], b);
  auto server = makeServer(dir);
  ASSERT_TRUE(server);
  ASSERT_EQ(server->resumeReport().problems.size(), 1u);
  EXPECT_NE(server->resumeReport().problems[0].find(entries[0]), std::string::npos);
  EXPECT_EQ(server->resumeReport().journal_replayed, 1u);
  EXPECT_EQ(server->pending(), 1u);
}

TEST(Checkpoint, ParamsValidate) {
  CheckpointParams p;
  EXPECT_TRUE(p.validate());
  p.keep = 1;
  EXPECT_FALSE(p.validate());
  p.keep = 2;
  p.period_s = -1;
  EXPECT_FALSE(p.validate());
}

/// Mutated bodies (no CRC in the way) must give an error or a state that saves
/// and loads again; never a crash.
TEST(Checkpoint, FuzzedStateNeverCrashesTheDecoders) {
  auto small = makeServer();
  ASSERT_TRUE(small);
  feed(small.get(), 0, 4);
  feed(small.get(), 4, 5, /*process=*/false);
  const std::vector<std::uint8_t> body = small->saveState();
  const std::vector<std::uint8_t> map = small->map().toBytes();
  // The map block carries its own CRC (fuzzed on its own below): state edits go
  // around it, so that the other decoders are exercised.
  const std::size_t map_at = std::search(body.begin(), body.end(), map.begin(), map.begin() + 4) - body.begin();
  ASSERT_LT(map_at, body.size());
  const std::size_t map_end = map_at + map.size();
  std::mt19937_64 rng(11);
  int loaded = 0, refused = 0, maps_loaded = 0;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(8);
  for (int it = 0; it < 400 && std::chrono::steady_clock::now() < deadline; ++it) {
    const bool is_map = it % 2 == 1;
    std::vector<std::uint8_t> b = is_map ? map : body;
    const int edits = 1 + static_cast<int>(rng() % 4);
    for (int e = 0; e < edits; ++e) {
      std::size_t at = rng() % b.size();
      if (!is_map && at >= map_at - 8 && at < map_end && b.size() == body.size())
        at = rng() % 2 ? rng() % (map_at - 8) : map_end + rng() % (b.size() - map_end);
      switch (rng() % 4) {
        case 0: b[at] ^= static_cast<std::uint8_t>(1u << (rng() % 8)); break;
        case 1: b[at] = static_cast<std::uint8_t>(rng()); break;
        case 2: b.resize(at); break;
        default:  // a count or length made huge
          for (std::size_t k = at; k < at + 8 && k < b.size(); ++k) b[k] = 0xff;
      }
      if (b.empty()) b.push_back(0);
    }
    if (is_map) {
      if (b.size() >= 4) resealCrc(&b);
      if (auto m = GlobalMap::fromBytes(b, "fuzz")) {
        ++maps_loaded;
        EXPECT_TRUE(GlobalMap::fromBytes(m->toBytes(), "again").ok());
      }
      continue;
    }
    auto s = makeServer();
    const Status st = s->loadState(b);
    if (refused < 3 && !st) std::printf("refused: %s\n", st.error().c_str());
    if (st) {
      ++loaded;
      auto again = makeServer();
      EXPECT_TRUE(again->loadState(s->saveState()));
      s->process(1e3);  // and it still works
    } else {
      ++refused;
    }
  }
  EXPECT_GT(refused, 0);
  std::printf("fuzz: %d states loaded, %d refused, %d maps loaded\n", loaded, refused, maps_loaded);
}

}  // namespace
}  // namespace server
}  // namespace hermes
