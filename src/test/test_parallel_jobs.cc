// runParallelJobs (parallel_jobs.h): every job once, each writing its own slot,
// for any thread count; a job that throws reaches the caller after every
// thread is joined (before: a joinable std::thread destroyed during unwinding
// terminated the process - the soak's server died of OpenGV's length_error
// thrown inside a parallel loop-closure batch).
#include <gtest/gtest.h>

#include <atomic>
#include <stdexcept>
#include <vector>

#include "hermes/core/parallel_jobs.h"

using namespace hermes;

TEST(ParallelJobs, EveryJobOnceForAnyThreadCount) {
  for (int threads : {1, 2, 3, 8}) {
    std::vector<int> out(37, 0);
    runParallelJobs(out.size(), threads, [&](std::size_t i) { out[i] += static_cast<int>(i) + 1; });
    for (std::size_t i = 0; i < out.size(); ++i) EXPECT_EQ(out[i], static_cast<int>(i) + 1) << threads;
  }
}

TEST(ParallelJobs, AJobThatThrowsReachesTheCallerWithEveryThreadJoined) {
  for (int threads : {1, 2, 4}) {
    std::atomic<int> ran{0};
    EXPECT_THROW(runParallelJobs(64, threads,
                                 [&](std::size_t i) {
                                   ++ran;
                                   if (i == 5) throw std::length_error("vector::reserve");
                                 }),
                 std::length_error)
        << threads;
    EXPECT_GE(ran.load(), 6) << threads;  // jobs 0..5 at least
    EXPECT_LE(ran.load(), 64) << threads;
  }
}
