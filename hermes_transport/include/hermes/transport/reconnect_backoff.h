// Waits between connection attempts: `min_s` after the first failure, doubling
// with every further one up to `max_s`; a successful connection starts over.
// No jitter: the robots' attempts are spread by their own outages already, and
// a deterministic schedule keeps the tests exact.
#pragma once

#include <algorithm>

namespace hermes::transport {

class ReconnectBackoff {
 public:
  ReconnectBackoff(double min_s, double max_s) : min_s_(min_s), max_s_(max_s) {}

  /// An attempt failed (or a connection was lost) at `now`: the next attempt is
  /// allowed at the returned time.
  double failed(double now) {
    const double wait = std::min(max_s_, min_s_ * static_cast<double>(1u << std::min(failures_, 20u)));
    ++failures_;
    next_ = now + wait;
    return next_;
  }
  void succeeded() {
    failures_ = 0;
    next_ = 0;
  }
  bool mayTry(double now) const { return now >= next_; }
  double nextAttempt() const { return next_; }
  unsigned failures() const { return failures_; }

 private:
  double min_s_, max_s_;
  unsigned failures_ = 0;
  double next_ = 0;
};

}  // namespace hermes::transport
