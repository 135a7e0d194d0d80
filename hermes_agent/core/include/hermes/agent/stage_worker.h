// One stage of the agent pipeline run by a worker thread (DESIGN §9, agent
// threads): a bounded FIFO of jobs with a written overflow policy, and a
// synchronous mode in which push() runs the job at once in the caller's thread
// (tests, the offline runner: deterministic).
//
// Overflow policy: the queue holds at most `capacity` waiting jobs (the one
// being run is not counted). A job pushed onto a full queue is never dropped
// and never blocks the caller: it is folded into the newest waiting job by the
// stage's merge function (e.g. two windows become one window).
//
// Shutdown: the destructor (or stop()) lets the thread finish the job it runs
// and every job still queued, then joins it. waitIdle() waits for the same
// without stopping the thread.
#pragma once

#include <algorithm>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <mutex>
#include <thread>
#include <utility>

#include "hermes/core/status.h"

namespace hermes::agent {

/// Counters of one stage (a consistent copy: StageWorker::stats()).
struct StageStats {
  std::int64_t pushed = 0;      ///< jobs handed to the stage
  std::int64_t run = 0;         ///< jobs finished
  std::int64_t merged = 0;      ///< jobs folded into a waiting one (queue full)
  std::size_t high_water = 0;   ///< most jobs waiting at once
};

template <typename Job>
class StageWorker {
 public:
  using Run = std::function<void(Job& job)>;
  /// Folds `incoming` into `waiting` (the newest queued job) when the queue is full.
  using Merge = std::function<void(Job& waiting, Job&& incoming)>;

  /// `parallel` false: no thread, push() runs the job immediately.
  StageWorker(bool parallel, std::size_t capacity, Run run, Merge merge)
      : parallel_(parallel), capacity_(capacity), run_(std::move(run)), merge_(std::move(merge)) {
    HERMES_CHECK(capacity_ >= 1, "stage worker: capacity must be >= 1");
    HERMES_CHECK(static_cast<bool>(run_), "stage worker: no run function");
    if (parallel_) thread_ = std::thread([this] { loop(); });
  }
  StageWorker(const StageWorker&) = delete;
  StageWorker& operator=(const StageWorker&) = delete;
  ~StageWorker() { stop(); }

  /// Never blocks on the job being run (only on the queue's short lock).
  void push(Job job) {
    if (!parallel_) {
      {
        std::lock_guard<std::mutex> l(mu_);
        ++stats_.pushed;
        stats_.high_water = std::max<std::size_t>(stats_.high_water, 1);
      }
      run_(job);
      std::lock_guard<std::mutex> l(mu_);
      ++stats_.run;
      return;
    }
    {
      std::lock_guard<std::mutex> l(mu_);
      HERMES_CHECK(!stopping_, "stage worker: push after stop");
      ++stats_.pushed;
      if (queue_.size() >= capacity_ && merge_) {
        merge_(queue_.back(), std::move(job));
        ++stats_.merged;
      } else {
        queue_.push_back(std::move(job));
      }
      stats_.high_water = std::max(stats_.high_water, queue_.size());
    }
    wake_.notify_one();
  }

  /// Waits until no job is queued or running.
  void waitIdle() {
    std::unique_lock<std::mutex> l(mu_);
    idle_.wait(l, [this] { return queue_.empty() && !running_; });
  }

  /// True when no job is queued or running.
  bool idle() const {
    std::lock_guard<std::mutex> l(mu_);
    return queue_.empty() && !running_;
  }

  /// Runs what is queued, then ends the thread (idempotent).
  void stop() {
    {
      std::lock_guard<std::mutex> l(mu_);
      if (stopping_ && !thread_.joinable()) return;
      stopping_ = true;
    }
    wake_.notify_one();
    if (thread_.joinable()) thread_.join();
  }

  StageStats stats() const {
    std::lock_guard<std::mutex> l(mu_);
    return stats_;
  }
  bool parallel() const { return parallel_; }

 private:
  void loop() {
    std::unique_lock<std::mutex> l(mu_);
    while (true) {
      wake_.wait(l, [this] { return stopping_ || !queue_.empty(); });
      if (queue_.empty()) break;  // stopping and drained
      Job job = std::move(queue_.front());
      queue_.pop_front();
      running_ = true;
      l.unlock();
      run_(job);
      l.lock();
      running_ = false;
      ++stats_.run;
      if (queue_.empty()) idle_.notify_all();
    }
    idle_.notify_all();
  }

  const bool parallel_;
  const std::size_t capacity_;
  Run run_;
  Merge merge_;
  mutable std::mutex mu_;
  std::condition_variable wake_, idle_;
  std::deque<Job> queue_;
  bool running_ = false, stopping_ = false;
  StageStats stats_;
  std::thread thread_;
};

}  // namespace hermes::agent
