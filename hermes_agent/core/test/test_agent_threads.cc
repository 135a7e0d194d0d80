// The threaded agent (DESIGN §9 agent threads) against the synchronous one on a
// rendered clip: same poses within a centimetre, every keyframe handed out in
// exactly one window, a held-back mapper or uplink never holds feed() back,
// the queues stay bounded, and a pipeline destroyed with work pending submits
// it all. Gates (not clocks) hold the workers: a feed() that waited for them
// would hang until the gate's timeout, which the tests then report.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <filesystem>
#include <map>
#include <mutex>
#include <set>
#include <thread>

#include "hermes/agent/agent_pipeline.h"
#include "hermes/agent/map_buffer.h"
#include "hermes/core/evaluation.h"
#include "hermes/core/wire_format.h"
#include "rendered_clip.h"

using namespace hermes;
namespace fs = std::filesystem;

namespace {

/// Closed until open(); wait() reports whether it opened within the timeout.
class Gate {
 public:
  void open() {
    std::lock_guard<std::mutex> l(mu_);
    open_ = true;
    cv_.notify_all();
  }
  bool wait() {
    std::unique_lock<std::mutex> l(mu_);
    ++entered_;
    cv_.notify_all();
    return cv_.wait_for(l, std::chrono::seconds(120), [this] { return open_; });
  }
  /// Until someone waits at the gate `n` times (false after the timeout).
  bool waitEntered(int n) {
    std::unique_lock<std::mutex> l(mu_);
    return cv_.wait_for(l, std::chrono::seconds(120), [&] { return entered_ >= n; });
  }
  bool isOpen() const {
    std::lock_guard<std::mutex> l(mu_);
    return open_;
  }

 private:
  mutable std::mutex mu_;
  std::condition_variable cv_;
  bool open_ = false;
  int entered_ = 0;
};

/// 4 s of V1_01 (the drone moves and turns), rendered once per process.
const test::RenderedClip& clip() {
  static const test::RenderedClip c = [] {
    auto r = test::renderV101Clip("hermes_agent_threads_V1_01", 10.0, 4.0);
    if (!r.ok()) throw std::runtime_error(r.error());
    return std::move(*r);
  }();
  return c;
}

/// Raw windows (every keyframe and landmark, no budget) once a second.
agent::AgentPipelineParams windowParams(bool parallel, const std::string& spool) {
  agent::AgentPipelineParams p;
  p.setWindowPeriod(1.0);
  p.distill.strategy = "none";
  p.uplink.buffer.dir = spool;
  p.uplink.buffer.fsync = false;
  p.uplink.max_in_flight_mbytes = 1000;
  p.threads.parallel = parallel;
  return p;
}

/// The frames the uplink handed to the transport, decoded, by sequence number.
struct Captured {
  std::mutex mu;
  std::map<std::uint64_t, Submap> submaps;
  Gate* gate = nullptr;  ///< the first send waits here when set
  bool gate_timed_out = false;
};

agent::UplinkSender::Transport capture(Captured* c) {
  return [c](std::uint32_t, std::uint64_t seq, const std::vector<std::uint8_t>& frame) {
    if (c->gate && !c->gate->isOpen() && !c->gate->wait()) c->gate_timed_out = true;
    auto s = decodeSubmap(frame);
    ASSERT_TRUE(s.ok()) << s.error();
    std::lock_guard<std::mutex> l(c->mu);
    c->submaps[seq] = std::move(*s);
  };
}

std::string spoolDir(const std::string& name) {
  const std::string dir = ::testing::TempDir() + "/hermes_agent_threads_spool_" + name + "_" +
                          std::to_string(::getpid());
  fs::remove_all(dir);
  return dir;
}

std::unique_ptr<agent::AgentPipeline> makePipeline(const agent::AgentPipelineParams& p,
                                                   Captured* out) {
  auto pipeline = agent::AgentPipeline::create(p, "V1_01", clip().camera);
  if (!pipeline.ok()) throw std::runtime_error(pipeline.error());
  Status s = (*pipeline)->attachUplink(capture(out), clip().frames.front().stamp);
  if (!s) throw std::runtime_error(s.error());
  return std::move(*pipeline);
}

void feedAll(agent::AgentPipeline* p) {
  for (const CameraFrame& f : clip().frames) {
    auto r = p->feed(f);
    ASSERT_TRUE(r.ok()) << r.error();
  }
}

/// Every keyframe of the map in exactly one submap, in order.
void expectEveryKeyframeOnce(const Captured& c, std::size_t keyframes) {
  std::vector<KeyframeId> ids;
  for (const auto& [seq, s] : c.submaps)
    for (const Keyframe& kf : s.keyframes) ids.push_back(kf.id);
  ASSERT_EQ(ids.size(), keyframes);
  for (std::size_t i = 0; i < ids.size(); ++i) EXPECT_EQ(ids[i], KeyframeId(i));
}

double ateSe3(const agent::AgentPipeline& p) {
  eval::EvalParams ep;
  ep.align = eval::AlignMode::kSE3;
  auto e = eval::evaluateTrajectory(clip().groundtruth, p.trajectory(), ep, "V1_01");
  if (!e.ok()) throw std::runtime_error(e.error());
  return e->ate.trans_m.rmse;
}

}  // namespace

TEST(AgentThreads, ParallelTracksLikeSynchronous) {
  const std::size_t n = clip().frames.size();
  ASSERT_EQ(n, 80u);
  Captured sync_out, par_out;
  auto sync = makePipeline(windowParams(false, spoolDir("sync")), &sync_out);
  auto par = makePipeline(windowParams(true, spoolDir("par")), &par_out);
  EXPECT_FALSE(sync->parallel());
  EXPECT_TRUE(par->parallel());
  feedAll(sync.get());
  feedAll(par.get());
  sync->flushWindow();
  par->flushWindow();

  // Both track (>= 99 % of the frames) and the poses agree within a centimetre.
  for (const agent::AgentPipeline* p : {sync.get(), par.get()}) {
    EXPECT_EQ(p->frames(), std::int64_t(n));
    EXPECT_LE(double(p->lostFrames()), 0.01 * double(n));
  }
  ASSERT_EQ(sync->trajectory().size(), par->trajectory().size());
  double sq = 0;
  for (std::size_t i = 0; i < sync->trajectory().size(); ++i) {
    const StampedPose &a = sync->trajectory()[i], &b = par->trajectory()[i];
    ASSERT_EQ(a.t, b.t);
    sq += (a.T_W_B.translation() - b.T_W_B.translation()).squaredNorm();
  }
  const double diff = std::sqrt(sq / double(sync->trajectory().size()));
  const double ate_sync = ateSe3(*sync), ate_par = ateSe3(*par);
  std::printf("ATE se3: synchronous %.4f m, parallel %.4f m; pose difference RMS %.4f m\n",
              ate_sync, ate_par, diff);
  EXPECT_LT(std::abs(ate_par - ate_sync), 0.01);
  EXPECT_LT(diff, 0.01);

  // The mapper ran, and every keyframe is accounted for exactly once: a BA
  // of its own, merged into a later one, or skipped.
  const agent::AgentThreadStats st = par->threadStats();
  EXPECT_TRUE(st.parallel);
  EXPECT_EQ(st.frames_fed, std::int64_t(n));
  EXPECT_EQ(st.frames_tracked, par->frames() - par->lostFrames());
  EXPECT_GT(st.mapping.ba_jobs, 0);
  EXPECT_EQ(st.mapping.ba_jobs + st.mapping.merged + st.mapping.skipped, st.mapping.keyframes);
  EXPECT_EQ(st.mapping.keyframes + 1, std::int64_t(par->tracker().keyframes().size()));
  EXPECT_GT(sync->threadStats().mapping.ba_jobs, 0);
  EXPECT_FALSE(sync->threadStats().parallel);

  // Windows: consecutive, every keyframe handed out once, in both modes.
  const agent::WindowCounters ws = sync->windows(), wp = par->windows();
  // (The parallel cut waits for the newest keyframe's BA, so its windows may
  // end a keyframe earlier or later; each cut window is sent or merged.)
  EXPECT_GE(ws.sent, 4);
  EXPECT_EQ(ws.sent, ws.windows);
  EXPECT_LE(std::abs(wp.windows - ws.windows), 1);
  EXPECT_EQ(wp.failed, 0);
  EXPECT_EQ(wp.sent + st.windows.merged, wp.windows);
  expectEveryKeyframeOnce(sync_out, sync->tracker().keyframes().size());
  expectEveryKeyframeOnce(par_out, par->tracker().keyframes().size());
  EXPECT_EQ(sync->timings().count("distill"), std::size_t(ws.windows));
  EXPECT_EQ(par->timings().count("distill"), std::size_t(wp.sent));
  EXPECT_EQ(par->timings().count("track"), n);
}

// A mapper held at its first BA: every frame is still tracked at once (feed()
// would hang at the gate otherwise), keyframes wait and are merged into the
// next BA once the mapper is free; windows stop at the last adjusted keyframe
// meanwhile, and the flush hands out everything.
TEST(AgentThreads, HeldMapperDoesNotHoldTracking) {
  Gate gate;
  bool mapper_timed_out = false;
  Captured out;
  auto p = makePipeline(windowParams(true, spoolDir("held_mapper")), &out);
  ASSERT_TRUE(p->setMapperHook([&] {
                 if (!gate.isOpen() && !gate.wait()) mapper_timed_out = true;
               }).ok());
  feedAll(p.get());
  ASSERT_TRUE(gate.waitEntered(1)) << "the first BA never started";
  EXPECT_FALSE(gate.isOpen());
  agent::AgentThreadStats st = p->threadStats();
  EXPECT_EQ(st.frames_fed, std::int64_t(clip().frames.size()));
  EXPECT_EQ(p->lostFrames(), 0);
  EXPECT_EQ(st.mapping.ba_jobs, 0) << "nothing can be applied while the BA is held";
  EXPECT_GE(st.mapping.keyframes, 4);
  EXPECT_EQ(st.mapping.max_waiting, st.mapping.keyframes - 1)
      << "every keyframe after the held one waits";
  EXPECT_EQ(p->tracker().mappedKeyframes(), 1u) << "windows end at the last adjusted keyframe";
  EXPECT_LE(p->windows().sent, 1);

  gate.open();
  p->flushWindow();
  EXPECT_FALSE(mapper_timed_out);
  st = p->threadStats();
  EXPECT_EQ(st.mapping.ba_jobs, 2) << "the held job, then one for all the waiting keyframes";
  EXPECT_EQ(st.mapping.ba_jobs + st.mapping.merged + st.mapping.skipped, st.mapping.keyframes);
  EXPECT_GT(st.mapping.skipped, 0) << "more keyframes waited than one BA window frees";
  EXPECT_EQ(p->tracker().mappedKeyframes(), p->tracker().keyframes().size());
  expectEveryKeyframeOnce(out, p->tracker().keyframes().size());
}

// An uplink whose transport is stuck: the window queue stays within its
// capacity by merging windows, tracking goes on; the pipeline is then destroyed
// with windows still queued and submits every one of them (nothing dropped).
TEST(AgentThreads, HeldUplinkMergesWindowsAndShutdownSubmitsThem) {
  Gate gate;
  Captured out;
  out.gate = &gate;
  agent::AgentPipelineParams params = windowParams(true, spoolDir("held_uplink"));
  params.setWindowPeriod(0.25);
  params.threads.window_queue = 2;
  auto p = makePipeline(params, &out);
  feedAll(p.get());
  ASSERT_TRUE(gate.waitEntered(1)) << "no window reached the transport";
  EXPECT_FALSE(gate.isOpen());
  EXPECT_EQ(p->lostFrames(), 0);
  const agent::AgentThreadStats st = p->threadStats();
  std::printf("windows queued %lld, merged %lld, run %lld, high water %zu\n",
              static_cast<long long>(st.windows.pushed), static_cast<long long>(st.windows.merged),
              static_cast<long long>(st.windows.run), st.windows.high_water);
  EXPECT_GE(st.windows.pushed, 4);
  EXPECT_GT(st.windows.merged, 0);
  EXPECT_LE(st.windows.high_water, 2u);
  EXPECT_EQ(st.windows.run, 0) << "the first window is still at the transport";
  const std::size_t keyframes = p->tracker().keyframes().size();
  const std::int64_t jobs = st.windows.pushed - st.windows.merged;

  gate.open();
  p.reset();  // no flush: the destructor runs the queued windows and joins
  EXPECT_FALSE(out.gate_timed_out);
  ASSERT_EQ(std::int64_t(out.submaps.size()), jobs);
  // Windows hand out keyframes in order without gaps up to the last cut one.
  std::vector<KeyframeId> ids;
  for (const auto& [seq, s] : out.submaps)
    for (const Keyframe& kf : s.keyframes) ids.push_back(kf.id);
  ASSERT_FALSE(ids.empty());
  for (std::size_t i = 0; i < ids.size(); ++i) EXPECT_EQ(ids[i], KeyframeId(i));
  EXPECT_LE(ids.size(), keyframes);
  // Every submitted window is in the spool (none acknowledged).
  agent::MapBufferParams bp = params.uplink.buffer;
  auto spool = agent::MapBuffer::open(bp);
  ASSERT_TRUE(spool.ok()) << spool.error();
  EXPECT_EQ(std::int64_t(spool->pendingCount()), jobs);
}

// The stage itself: synchronous mode runs in the caller's thread; in parallel
// mode jobs run in order, a full queue folds the newest jobs into its last
// waiting one, and stop() runs everything queued before the thread ends.
TEST(StageWorker, OrderMergePolicyAndDrainingStop) {
  const std::thread::id caller = std::this_thread::get_id();
  std::vector<std::thread::id> where;
  agent::StageWorker<int> sync(false, 1, [&](int&) { where.push_back(std::this_thread::get_id()); },
                               nullptr);
  sync.push(1);
  sync.push(2);
  ASSERT_EQ(where.size(), 2u);
  EXPECT_EQ(where[0], caller);
  EXPECT_EQ(sync.stats().run, 2);

  Gate gate;
  bool timed_out = false;
  std::vector<std::vector<int>> ran;  // written by the worker, read after stop()
  {
    agent::StageWorker<std::vector<int>> w(
        true, 2,
        [&](std::vector<int>& job) {
          if (!gate.isOpen() && !gate.wait()) timed_out = true;
          ran.push_back(job);
        },
        [](std::vector<int>& waiting, std::vector<int>&& incoming) {
          waiting.insert(waiting.end(), incoming.begin(), incoming.end());
        });
    w.push({1});
    ASSERT_TRUE(gate.waitEntered(1));  // job 1 runs and is held: 2.. queue up
    for (int i = 2; i <= 6; ++i) w.push({i});
    const agent::StageStats st = w.stats();
    EXPECT_EQ(st.pushed, 6);
    EXPECT_EQ(st.merged, 3);  // 2 and 3 wait; 4, 5, 6 join 3
    EXPECT_EQ(st.high_water, 2u);
    EXPECT_EQ(st.run, 0);
    EXPECT_FALSE(w.idle());
    gate.open();
    w.stop();
    EXPECT_EQ(w.stats().run, 3);
  }
  EXPECT_FALSE(timed_out);
  ASSERT_EQ(ran.size(), 3u);
  EXPECT_EQ(ran[0], std::vector<int>({1}));
  EXPECT_EQ(ran[1], std::vector<int>({2}));
  EXPECT_EQ(ran[2], std::vector<int>({3, 4, 5, 6}));
}

TEST(AgentThreads, ThreadParamsAreReadAndChecked) {
  Config c;
  ASSERT_TRUE(c.applyOverride("agent.parallel=true"));
  ASSERT_TRUE(c.applyOverride("agent.window_queue=3"));
  agent::AgentThreadParams p;
  ASSERT_TRUE(p.read(c));
  EXPECT_TRUE(p.parallel);
  EXPECT_EQ(p.window_queue, 3);
  ASSERT_TRUE(c.applyOverride("agent.window_queue=0"));
  Status s = p.read(c);
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().find("agent.window_queue"), std::string::npos) << s.error();
  EXPECT_FALSE(agent::AgentPipelineParams().threads.parallel) << "synchronous by default";

  // setParallel only before the first frame.
  auto pipeline = agent::AgentPipeline::create(agent::AgentPipelineParams(), "a", clip().camera);
  ASSERT_TRUE(pipeline.ok()) << pipeline.error();
  ASSERT_TRUE((*pipeline)->setParallel(true));
  EXPECT_TRUE((*pipeline)->parallel());
  ASSERT_TRUE((*pipeline)->feed(clip().frames.front()).ok());
  EXPECT_FALSE((*pipeline)->setParallel(false));
}
