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
#include <thread>

#include "hermes/server/server_worker.h"
#include "support/multi_agent_fixture.h"

namespace hermes {
namespace server {
namespace {

const std::string kGt = std::string(HERMES_TRAJECTORY_DIR) + "/";

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

std::unique_ptr<Server> makeServer(const std::string& checkpoint_dir = "", int closure_budget = 0,
                                   int full_every = 5) {
  ServerParams params;
  params.map.pose_graph.full_every = full_every;
  params.checkpoint.dir = checkpoint_dir;
  params.map.closure_budget = closure_budget;
  params.map.closure_budget_swarm = 0;  // a fixed budget or none: the same in both modes whatever the clock
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
  // One view per merge, and one per full pose-graph solve between merges.
  const std::size_t full_between =
      threaded.server().timings().count("pose_graph_full") - 1;  // the first solve is a merge's
  EXPECT_EQ(published.size(), frames.size() + full_between);
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

// server.pose_graph.full_between_merges: a merge solves the pose graph only
// incrementally (after the first solve); the full solve falls due and runs
// once no submap waits.
TEST(ServerWorker, MergesSolveIncrementallyTheFullSolveRunsBetweenThem) {
  const auto frames = schedule();
  std::unique_ptr<Server> server = makeServer("", 0, /*full_every=*/2);
  ASSERT_TRUE(server);
  for (std::size_t i = 0; i < frames.size(); ++i)
    ASSERT_EQ(server->onFrame(frames[i]->data(), frames[i]->size(), nullptr, 1.0).verdict, ArrivalVerdict::kAccept);
  bool was_due = false;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const int solves = server->mapManager().graphDiagnostics().solves;
    ASSERT_EQ(server->process(2.0 + i, 1), 1);  // a submap waits after it: no full solve
    const GraphDiagnostics& g = server->mapManager().graphDiagnostics();
    if (solves > 0 && g.solves > solves) {
      EXPECT_TRUE(g.last_incremental) << "merge " << i;
    }
    was_due = was_due || server->fullSolveDue();
  }
  ASSERT_TRUE(was_due) << "the fixture should make a full solve due";
  const std::size_t full_before = server->timings().count("pose_graph_full");
  EXPECT_EQ(server->process(99.0), 0);  // nothing waits: the full solve
  EXPECT_FALSE(server->fullSolveDue());
  EXPECT_EQ(server->timings().count("pose_graph_full"), full_before + 1);
  EXPECT_FALSE(server->mapManager().graphDiagnostics().last_incremental);
  EXPECT_EQ(server->counters().merge_errors, 0u) << server->counters().last_error;
}

// server.map.timing_window: a server of a day-long mission keeps the last W
// timing samples per stage, not one per merge since it started.
TEST(ServerWorker, TimingsKeepABoundedWindowPerStage) {
  const auto frames = schedule();
  ServerParams params;
  params.map.timing_window = 2;
  auto server = Server::create(params, HERMES_SOURCE_DIR);
  ASSERT_TRUE(server.ok()) << server.error();
  for (std::size_t i = 0; i < frames.size(); ++i) {
    ASSERT_EQ((*server)->onFrame(frames[i]->data(), frames[i]->size(), nullptr, 1.0 + i).verdict,
              ArrivalVerdict::kAccept);
    (*server)->process(1.0 + i);
  }
  const TimingStats t = (*server)->timings();
  ASSERT_GE(t.count("submap"), frames.size());  // count is every sample
  for (const auto& [stage, samples] : t.samples()) EXPECT_LE(samples.size(), 4u) << stage;
}

// The threaded server solves in full on a thread of its own while merges go
// on; a result lands on keyframes merged meanwhile by their trajectory's
// correction. The map ends where the synchronous server's does (within the
// fixture's noise: the solves see the graph at other moments).
TEST(ServerWorker, AFullSolveBesideTheMergesEndsWithTheSynchronousMap) {
  const auto frames = schedule();
  std::unique_ptr<Server> sync = makeServer("", 0, 2);
  ASSERT_TRUE(sync);
  std::atomic<double> now{0};
  ServerWorker threaded(makeServer("", 0, 2), ServerWorkerParams{}, [&now] { return now.load(); });
  for (std::size_t i = 0; i < frames.size(); ++i) {
    now = 1.0 + i;
    ASSERT_EQ(sync->onFrame(frames[i]->data(), frames[i]->size(), nullptr, now).verdict, ArrivalVerdict::kAccept);
    sync->process(now);
    ASSERT_EQ(threaded.onFrame(frames[i]->data(), frames[i]->size(), nullptr, now).verdict,
              ArrivalVerdict::kAccept);  // no waiting: merges and full solves overlap
  }
  threaded.waitIdle();
  threaded.stop();
  const Server& t = threaded.server();
  EXPECT_EQ(t.counters().merge_errors, 0u) << t.counters().last_error;
  EXPECT_EQ(t.counters().merged, frames.size());
  EXPECT_FALSE(t.fullSolveDue());
  EXPECT_GE(t.timings().count("pose_graph_full"), 2u);
  const MapSummary a = summarize(*sync), b = summarize(t);
  ASSERT_GT(a.poses.size(), 0u);
  EXPECT_EQ(a.keyframes, b.keyframes);
  std::size_t common = 0;
  double worst = 0;
  for (const auto& [key, T] : a.poses) {
    auto it = b.poses.find(key);
    if (it == b.poses.end()) continue;
    ++common;
    ASSERT_TRUE(it->second.translation().allFinite());
    worst = std::max(worst, (T.translation() - it->second.translation()).norm());
  }
  EXPECT_GE(common, a.poses.size() * 9 / 10);
  EXPECT_LT(worst, 0.05) << "threaded and synchronous maps differ by " << worst << " m";
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

// The tend hook (the node's downlink plan): on the merge thread after every
// merge, and every tend_period_s while no submap comes.
TEST(ServerWorker, TendRunsAfterMergesAndWhileIdle) {
  const auto frames = schedule();
  std::atomic<int> calls{0};
  std::atomic<std::size_t> merged_seen{0};
  ServerWorkerParams p;
  p.tend_period_s = 0.05;
  ServerWorker worker(
      makeServer(), p, [] { return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count(); },
      nullptr, [&](const Server& s, double) {
        ++calls;
        merged_seen = s.counters().merged;
      });
  for (std::size_t i = 0; i < 3; ++i) worker.onFrame(frames[i]->data(), frames[i]->size(), nullptr, 1.0 + i);
  worker.waitIdle();
  EXPECT_EQ(merged_seen.load(), 3u) << "the hook saw the map after the last merge";
  const int after_merges = calls.load();
  EXPECT_GE(after_merges, 3);
  std::this_thread::sleep_for(std::chrono::milliseconds(400));
  EXPECT_GE(calls.load(), after_merges + 3) << "idle: every tend_period_s";
  worker.stop();
}

}  // namespace
}  // namespace server
}  // namespace hermes
