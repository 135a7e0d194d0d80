// The server with its merging on a thread of its own (DESIGN.md §9, issue 17:
// merging never blocks acknowledgements). Owns a Server; the transport calls
// onFrame() from its receiving thread and gets the verdict to acknowledge at
// once (decode, dedup, auth, admission, journal, queue: Server::onFrame),
// while the merge thread runs Server::process() one submap at a time.
//
// Synchronous mode (params.parallel = false): no thread; the owner calls
// process() (tests; deterministic like the offline runner, which drives a
// Server the same way).
//
// Locking (see also the top of server.h): the Server's intake mutex guards
// what onFrame() and process() share - bookkeeper, credibility queue, pending
// submaps, quotas, receiver stats, journal - and is held by the merge thread
// only to take a submap, to mark it applied, to anchor agents and to copy the
// intake state for a checkpoint: an onFrame() waits for those short sections,
// never for loops, PCM or a pose-graph solve. The map belongs to the merge
// thread; readers on other threads get a MergedView (server_outputs.h) the
// merge thread publishes after every merge (view(); on_merged is also called
// with it, on the merge thread). metrics() combines the view's merge part with
// the intake part read live under the intake lock. The worker's own mutex only
// guards its wake-up flags and the view pointer (lock order: worker, then
// intake; never the other way round).
//
// Falling behind: accepted submaps wait in the credibility queue (merged in
// credibility order with aging, credibility.h). Its bound is per robot,
// server.queue.* (admission.h): a submap beyond its robot's share is refused
// with reason "quota" and no acknowledgement; the agent keeps it in its spool
// and resends. Nothing is dropped, nothing merged together, and onFrame()
// never blocks on a full queue.
//
// Shutdown: stop() lets the merge thread finish the merge it runs and ends it;
// what is still queued stays queued (Server::pending(); journalled when
// checkpoints are on). The owner then has the Server to itself (server()): it
// may merge the rest with process(), write a checkpoint (Server::checkpoint,
// which covers the queued submaps too) and the results.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <future>
#include <thread>

#include "hermes/core/metrics.h"
#include "hermes/server/server.h"
#include "hermes/server/server_outputs.h"

namespace hermes {
namespace server {

struct ServerWorkerParams {
  bool parallel = true;               ///< false: no thread, the owner calls process()
  std::size_t latency_window = 2000;  ///< acknowledgement latencies kept for median / p95 [samples]
  double tend_period_s = 1.0;         ///< the tend hook runs at least this often while idle [s]
  Status validate() const;
};

class ServerWorker {
 public:
  /// Now [s] for the merges (queue aging, checkpoint period).
  using Clock = std::function<double()>;
  /// After every merge (on the merging thread): the new view.
  using Merged = std::function<void(const MergedView&)>;
  /// On the merging thread after every merge and at least every
  /// params.tend_period_s while idle: work that reads the map between merges
  /// (the downlink's plan). Reading the intake state needs lockIntake().
  using Tend = std::function<void(const Server&, double now)>;

  ServerWorker(std::unique_ptr<Server> server, ServerWorkerParams params, Clock clock,
               Merged on_merged = nullptr, Tend tend = nullptr);
  ServerWorker(const ServerWorker&) = delete;
  ServerWorker& operator=(const ServerWorker&) = delete;
  ~ServerWorker();

  /// One received frame (one receiving thread at a time): the verdict to
  /// acknowledge, without waiting for a merge.
  ReceiveResult onFrame(const std::uint8_t* data, std::size_t size, const SubmapHeader* claimed,
                        double now);
  /// Receive -> acknowledgement sent, as the transport measured it [ms]
  /// (metrics(): timings_ms "ack_latency"). Any thread.
  void recordAckLatency(double ms);

  /// Synchronous mode, or after stop(): merges up to max_submaps (< 0: all)
  /// in the caller's thread and publishes the view. Returns how many merged.
  int process(double now, int max_submaps = -1);
  /// Parallel mode: returns once nothing is queued and no merge runs (or the
  /// thread was stopped). Tests and benches.
  void waitIdle();
  /// Asks the merge thread to end after the merge it runs; returns at once.
  void requestStop();
  /// requestStop() and waits for the thread to end (idempotent; the
  /// destructor calls it). Queued submaps stay queued.
  void stop();
  bool running() const { return running_; }

  /// The newest view (never null; before any merge: the state at start).
  std::shared_ptr<const MergedView> view() const;
  /// The server's metrics (serverMetrics) plus timings_ms "ack_latency".
  RunMetrics metrics() const;
  /// The server itself: only while no merge thread runs (checked).
  Server& server();
  const Server& server() const;

 private:
  void loop();
  /// Publishes a new view when a merge happened since the last one (or `force`).
  void publish(bool force = false);
  /// The full pose-graph solve on a thread of its own (merge thread only):
  /// applies a finished one, starts a due one. Returns true while one runs.
  bool tendFullSolve();

  std::unique_ptr<Server> server_;
  const ServerWorkerParams params_;
  Clock clock_;
  Merged on_merged_;
  Tend tend_;
  double last_tend_ = -1e300;  ///< merge thread
  /// The tend hook when due (or `force`), merge thread.
  void tend(bool force);
  mutable std::mutex mu_;  ///< work_, view_, acks_
  std::condition_variable wake_, idle_;
  bool work_ = false;     ///< a submap was queued since the merge thread last looked
  bool merging_ = false;  ///< the merge thread is between wake-up and idle
  std::atomic<bool> stopping_{false}, running_{false};
  std::shared_ptr<const MergedView> view_;
  std::size_t attempts_seen_ = 0;  ///< merges + merge errors at the last view (merge thread)
  TimingStats acks_;
  std::thread thread_;
  std::shared_ptr<FullSolve> full_solve_;  ///< running on full_solve_thread_ (merge thread's)
  std::future<void> full_solve_done_;
};

}  // namespace server
}  // namespace hermes
