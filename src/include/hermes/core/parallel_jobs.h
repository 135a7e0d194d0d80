// Runs n independent jobs on up to `threads` threads (the calling thread one
// of them) and returns when all are done. Each job writes only its own slot of
// a result array, so results are the same in the same order for any thread
// count; threads <= 1 runs them in the calling thread, in order (the
// synchronous mode of deterministic tests). No queue: the jobs are known up
// front and taken by index. A job that throws: the threads stop taking jobs,
// all are joined, and the first exception is rethrown on the caller.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <exception>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace hermes {

inline void runParallelJobs(std::size_t n, int threads, const std::function<void(std::size_t)>& job) {
  const std::size_t workers = std::min<std::size_t>(threads > 1 ? threads : 1, n);
  if (workers <= 1) {
    for (std::size_t i = 0; i < n; ++i) job(i);
    return;
  }
  std::atomic<std::size_t> next{0};
  std::exception_ptr failed;  // the first job that threw; the others stop taking jobs
  std::mutex failed_mu;
  auto work = [&] {
    try {
      for (std::size_t i = next++; i < n; i = next++) job(i);
    } catch (...) {
      std::lock_guard<std::mutex> lock(failed_mu);
      if (!failed) failed = std::current_exception();
      next = n;
    }
  };
  std::vector<std::thread> pool;
  pool.reserve(workers - 1);
  for (std::size_t w = 1; w < workers; ++w) pool.emplace_back(work);
  work();
  for (std::thread& t : pool) t.join();
  if (failed) std::rethrow_exception(failed);  // on the caller, every thread joined
}

}  // namespace hermes
