// ServerWorker (server_worker.h): merging on its own thread never holds up an
// acknowledgement; threaded and synchronous runs end with the same map;
// stopping with submaps queued loses none of them.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <filesystem>
#include <future>
#include <mutex>

#include "hermes/server/server_worker.h"
#include "support/multi_agent_fixture.h"

namespace hermes {
namespace server {
namespace {

const std::string kGt = std::string(HERMES_SHARED_DATA_DIR) + "/euroc_gt/";

/// Two robots in one hall, a few submaps each.
const fixture::Fixture& hall() {
  static const fixture::Fixture fx = [] {
    auto made = fixture::makeFixture({{kGt + "MH_01_easy.txt", 0.0, 16.0, -1},
                                      {kGt + "MH_02_easy.txt", 0.0, 16.0, -1}},
                                     fixture::Options{});
    EXPECT_TRUE(made.ok()) << (made ? "" : made.error());
    return made ? std::move(*made) : fixture::Fixture{};
  }();
  return fx;
}

std::vector<const std::vector<std::uint8_t>*> schedule() { return fixture::roundRobin(hall()); }

std::unique_ptr<Server> makeServer(const std::string& checkpoint_dir = "", int closure_budget = 0) {
  ServerParams params;
  params.checkpoint.dir = checkpoint_dir;
  params.map.closure_budget = closure_budget;
  auto server = Server::create(params, HERMES_SOURCE_DIR);
  EXPECT_TRUE(server.ok()) << (server ? "" : server.error());
  return server ? std::move(*server) : nullptr;
}

/// Holds merges inside the map manager (its candidate hook runs in every
/// merge) until opened: a merge that takes as long as the test wants.
class MergeGate {
 public:
  void install(Server* server) {
    server->mapManager().setCandidateHook([this](const KeyframeKey&, std::vector<PlaceCandidate>*) {
      std::unique_lock<std::mutex> l(mu_);
      entered_ = true;
      changed_.notify_all();
      changed_.wait(l, [this] { return open_; });
    });
  }
  /// True once a merge is held at the gate (false: none came within a minute).
  bool waitEntered() {
    std::unique_lock<std::mutex> l(mu_);
    return changed_.wait_for(l, std::chrono::minutes(1), [this] { return entered_; });
  }
  void open() {
    std::lock_guard<std::mutex> l(mu_);
    open_ = true;
    changed_.notify_all();
  }
  bool isOpen() const {
    std::lock_guard<std::mutex> l(mu_);
    return open_;
  }

 private:
  mutable std::mutex mu_;
  std::condition_variable changed_;
  bool entered_ = false, open_ = false;
};

struct MapSummary {
  std::size_t keyframes = 0, landmarks = 0, loops = 0, accepted = 0;
  std::map<KeyframeKey, SE3> poses;  ///< anchored keyframes
};

MapSummary summarize(const Server& s) {
  MapSummary m;
  for (const auto& [tid, t] : s.map().trajectories) {
    m.keyframes += t.keyframes.size();
    m.landmarks += t.landmarks.size();
    if (!t.anchored) continue;
    for (const auto& [id, kf] : t.keyframes) m.poses[KeyframeKey{t.agent, t.session, id}] = kf.T_W_C;
  }
  m.loops = s.map().loops.size();
  m.accepted = s.mapManager().loopsAccepted();
  return m;
}

TEST(ServerWorker, AcknowledgesWhileAMergeRuns) {
  auto server = makeServer();
  ASSERT_TRUE(server);
  MergeGate gate;
  gate.install(server.get());
  ServerWorker worker(std::move(server), ServerWorkerParams{}, [] { return 1.0; });
  const auto frames = schedule();
  ASSERT_GE(frames.size(), 4u);
  // The first submap's merge is held at the gate; the rest arrive meanwhile
  // and each must get its verdict at once (on another thread than the test's,
  // so that an acknowledgement that waits for the merge fails the test instead
  // of hanging it).
  auto acks = std::async(std::launch::async, [&] {
    std::vector<ReceiveResult> out;
    out.push_back(worker.onFrame(frames[0]->data(), frames[0]->size(), nullptr, 1.0));
    if (!gate.waitEntered()) return out;  // the merge never started
    for (std::size_t i = 1; i < frames.size(); ++i)
      out.push_back(worker.onFrame(frames[i]->data(), frames[i]->size(), nullptr, 1.0 + i));
    out.push_back(worker.onFrame(frames[1]->data(), frames[1]->size(), nullptr, 99.0));  // a resend
    return out;
  });
  const bool answered = acks.wait_for(std::chrono::minutes(1)) == std::future_status::ready;
  const bool merge_still_held = !gate.isOpen();
  gate.open();  // lets the merges go on (also when the acknowledgements hung)
  ASSERT_TRUE(answered) << "acknowledgements waited for the merge";
  EXPECT_TRUE(merge_still_held);
  const std::vector<ReceiveResult> results = acks.get();
  ASSERT_EQ(results.size(), frames.size() + 1) << "the first submap's merge never started";
  for (std::size_t i = 0; i + 1 < results.size(); ++i)
    EXPECT_EQ(results[i].verdict, ArrivalVerdict::kAccept) << "frame " << i << ": " << results[i].reason;
  EXPECT_EQ(results.back().verdict, ArrivalVerdict::kDuplicate);
  EXPECT_TRUE(results.back().acknowledge);
  worker.waitIdle();
  EXPECT_GE(worker.view()->version, frames.size() + 1);  // the start's view, then one per merge
  worker.stop();
  EXPECT_EQ(worker.server().counters().merged, frames.size());
  EXPECT_EQ(worker.server().pending(), 0u);
}

TEST(ServerWorker, ThreadedAndSynchronousEndWithTheSameMap) {
  const auto frames = schedule();
  auto sync_server = makeServer();
  ASSERT_TRUE(sync_server);
  ServerWorkerParams sync_params;
  sync_params.parallel = false;
  ServerWorker sync(std::move(sync_server), sync_params, [] { return 0.0; });
  std::atomic<double> now{0};
  std::vector<std::uint64_t> published;
  ServerWorker threaded(makeServer(), ServerWorkerParams{}, [&now] { return now.load(); },
                        [&](const MergedView& v) { published.push_back(v.version); });
  for (std::size_t i = 0; i < frames.size(); ++i) {
    now = 1.0 + i;
    EXPECT_EQ(sync.onFrame(frames[i]->data(), frames[i]->size(), nullptr, now).verdict, ArrivalVerdict::kAccept);
    sync.process(now);
    EXPECT_EQ(threaded.onFrame(frames[i]->data(), frames[i]->size(), nullptr, now).verdict,
              ArrivalVerdict::kAccept);
    threaded.waitIdle();  // one submap at a time: the same merge order
  }
  threaded.stop();
  EXPECT_EQ(published.size(), frames.size());
  const MapSummary a = summarize(sync.server()), b = summarize(threaded.server());
  EXPECT_GT(a.keyframes, 0u);
  EXPECT_GT(a.accepted, 0u) << "the fixture should close loops";
  EXPECT_EQ(a.keyframes, b.keyframes);
  EXPECT_EQ(a.landmarks, b.landmarks);
  EXPECT_EQ(a.loops, b.loops);
  EXPECT_EQ(a.accepted, b.accepted);
  ASSERT_EQ(a.poses.size(), b.poses.size());
  for (const auto& [key, T] : a.poses) {
    auto it = b.poses.find(key);
    ASSERT_NE(it, b.poses.end());
    EXPECT_LT((T.translation() - it->second.translation()).norm(), 1e-6);
  }
  // The view the outputs read is the map's.
  EXPECT_EQ(threaded.view()->landmarks.size(), threaded.server().map().landmarkPositionsWorld().size());
  EXPECT_EQ(sync.view()->poses.size(), threaded.view()->poses.size());
}

// server.map.closure_budget: the merge thread verifies the deferred closures
// once no submap waits, so it goes idle only when none is left.
TEST(ServerWorker, DeferredClosuresAreVerifiedBeforeTheThreadIdles) {
  const auto frames = schedule();
  std::unique_ptr<Server> server = makeServer("", 2);
  ASSERT_TRUE(server);
  std::atomic<int> deferred{0};
  server->mapManager().setAttemptHook([&](const LoopAttempt& a) {
    if (a.status == LoopStatus::kSkippedBudget) ++deferred;
  });
  std::atomic<double> now{0};
  ServerWorker worker(std::move(server), ServerWorkerParams{}, [&now] { return now.load(); });
  for (std::size_t i = 0; i < frames.size(); ++i) {
    now = 1.0 + i;
    EXPECT_EQ(worker.onFrame(frames[i]->data(), frames[i]->size(), nullptr, now).verdict,
              ArrivalVerdict::kAccept);
    worker.waitIdle();
  }
  worker.stop();  // the server is the test's again (waitIdle() saw the thread idle)
  EXPECT_EQ(worker.server().deferredClosures(), 0u);
  EXPECT_GT(deferred.load(), 0) << "a budget of 2 should defer closures on this fixture";
  EXPECT_GT(worker.server().mapManager().loopsAccepted(), 0u);
  EXPECT_EQ(worker.server().counters().merge_errors, 0u) << worker.server().counters().last_error;
}

TEST(ServerWorker, StopWithSubmapsQueuedLosesNone) {
  const std::string dir = ::testing::TempDir() + "/hermes_server_worker_stop";
  std::filesystem::remove_all(dir);
  const auto frames = schedule();
  {
    auto server = makeServer(dir);
    ASSERT_TRUE(server);
    MergeGate gate;
    gate.install(server.get());
    ServerWorker worker(std::move(server), ServerWorkerParams{}, [] { return 1.0; });
    for (std::size_t i = 0; i < frames.size(); ++i) {
      EXPECT_EQ(worker.onFrame(frames[i]->data(), frames[i]->size(), nullptr, 1.0 + i).verdict,
                ArrivalVerdict::kAccept);
      if (i == 0) {
        ASSERT_TRUE(gate.waitEntered());
      }
    }
    worker.requestStop();  // seen once the held merge ends: no other merge starts
    gate.open();
    worker.stop();
    EXPECT_EQ(worker.server().counters().merged, 1u);
    EXPECT_EQ(worker.server().pending(), frames.size() - 1);
    // No checkpoint at shutdown: the journal alone must hold the rest.
  }
  auto resumed = makeServer(dir);
  ASSERT_TRUE(resumed);
  EXPECT_TRUE(resumed->resumeReport().resumed);
  EXPECT_EQ(resumed->counters().merged + resumed->pending(), frames.size());
  resumed->process(100.0);
  auto reference = makeServer();
  ASSERT_TRUE(reference);
  for (std::size_t i = 0; i < frames.size(); ++i)
    reference->onFrame(frames[i]->data(), frames[i]->size(), nullptr, 1.0 + i);
  reference->process(100.0);
  EXPECT_EQ(summarize(*resumed).keyframes, summarize(*reference).keyframes);
  EXPECT_EQ(summarize(*resumed).landmarks, summarize(*reference).landmarks);
  std::filesystem::remove_all(dir);
}

TEST(ServerWorker, MetricsCarryTheAcknowledgementLatency) {
  ServerWorker worker(makeServer(), ServerWorkerParams{}, [] { return 0.0; });
  for (double ms : {1.0, 2.0, 3.0}) worker.recordAckLatency(ms);
  const RunMetrics m = worker.metrics();  // while the thread runs: view + intake
  ASSERT_TRUE(m.timings_ms.count("ack_latency"));
  EXPECT_EQ(m.timings_ms.at("ack_latency").count, 3);
  EXPECT_DOUBLE_EQ(m.timings_ms.at("ack_latency").median, 2.0);
  EXPECT_TRUE(m.bytes_total.has_value());
}

}  // namespace
}  // namespace server
}  // namespace hermes
