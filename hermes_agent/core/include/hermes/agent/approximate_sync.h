// Pairs two message streams by stamp: A (colour / left image) with B (depth /
// right image), as a robot publishes them on two topics.
//
// Pairing and drop policy (each stream must arrive in stamp order):
//   * A message whose stamp is not after the newest stamp already received on
//     its stream (repeated, out of order, NaN) is dropped: `out_of_order`.
//   * Each stream waits in a queue of `capacity` messages; pushing into a full
//     queue drops that queue's OLDEST message (`overflow_*`, also a `dropped_*`).
//   * The oldest waiting A is paired with the waiting B closest in stamp, if
//     |t_B - t_A| <= slop (ties: the older B). The pair is final once a B at or
//     after t_A has arrived (no later B can be closer), or once B's rhythm rules
//     a closer B out: the next B comes no earlier than the newest B + 0.8 x the
//     smallest of B's last 8 stamp intervals, and that is no closer to t_A
//     (so an RGB-D pair whose depth is a few ms early is not held back for the
//     next depth image, a whole frame later); until then A waits.
//     Each message is used once; B's older than the paired B are dropped, so
//     pop() hands out pairs in time order on both streams.
//   * A message that can no longer be paired is dropped (`dropped_*`): no
//     waiting message of the other stream lies within slop of it, and the newest
//     message received on the other stream is more than slop after it.
// The logic works on stamps only (StampPairer); ApproximateSync<A, B> keeps the
// payloads beside it. Synchronous, not thread-safe: callers lock.
#pragma once

#include <cstdint>
#include <deque>
#include <limits>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "hermes/core/status.h"

namespace hermes::agent {

struct SyncParams {
  double slop = 0.020;          ///< [s] largest stamp difference of a pair (stereo: ~0.001)
  int capacity = 10;            ///< messages waiting per stream
  int never_paired_after = 30;  ///< neverPaired() once both streams sent this many

  Status validate() const;
};

struct SyncStats {
  std::int64_t received_a = 0, received_b = 0;  ///< pushes, including dropped ones
  std::int64_t paired = 0;
  std::int64_t dropped_a = 0, dropped_b = 0;    ///< never paired (incl. overflow)
  std::int64_t overflow_a = 0, overflow_b = 0;  ///< of those: pushed out of a full queue
  std::int64_t out_of_order = 0;                ///< both streams
  double newest_a = std::numeric_limits<double>::quiet_NaN();  ///< newest stamp received [s]
  double newest_b = std::numeric_limits<double>::quiet_NaN();

  /// "paired 10, dropped A 1 (overflow 0), dropped B 2 (overflow 0), out of order 0".
  std::string summary() const;
};

/// The pairing logic on stamps alone. push() reports, in order, what happened
/// to the fronts of the two queues so that a caller can mirror them.
class StampPairer {
 public:
  enum class Op { kDropA, kDropB, kPair };  ///< pop front of A / of B / of both as a pair

  /// `params` must validate() (checked: a programmer error aborts).
  explicit StampPairer(const SyncParams& params);
  /// Appends the operations to *ops; false when the stamp was out of order
  /// (the message is not queued).
  bool pushA(double stamp, std::vector<Op>* ops) { return push(true, stamp, ops); }
  bool pushB(double stamp, std::vector<Op>* ops) { return push(false, stamp, ops); }
  /// Forgets the queues and the newest stamps (e.g. a bag restarted); keeps the counters.
  void reset();

  const SyncStats& stats() const { return stats_; }
  const SyncParams& params() const { return params_; }
  /// True when both streams sent at least never_paired_after messages and not
  /// one pair was made: the stamps do not match (wrong slop or topics).
  bool neverPaired() const;
  std::size_t waitingA() const { return a_.size(); }
  std::size_t waitingB() const { return b_.size(); }

 private:
  static constexpr int kRhythmGaps = 8;         ///< B intervals remembered
  static constexpr double kRhythmMargin = 0.8;  ///< next B >= newest + 0.8 x smallest interval

  bool push(bool is_a, double stamp, std::vector<Op>* ops);
  /// The smallest of B's last kRhythmGaps stamp intervals; NaN until known.
  double minGapB() const;
  /// True when no B still to come can be closer to ta than the newest one.
  bool nextBIsFarther(double ta) const;
  void match(std::vector<Op>* ops);
  void dropA(std::vector<Op>* ops);
  void dropB(std::vector<Op>* ops);

  SyncParams params_;
  SyncStats stats_;
  std::deque<double> a_, b_;  ///< waiting stamps, ascending
  std::deque<double> b_gaps_;  ///< B's last stamp intervals [s]
  bool have_a_ = false, have_b_ = false;
};

/// A pair handed out by ApproximateSync::pop().
template <class A, class B>
struct SyncedPair {
  double stamp_a = 0, stamp_b = 0;  ///< [s]
  A a;
  B b;
};

/// Typed front of StampPairer: push messages as they come, pop() pairs after
/// every push (pairs wait in an unbounded ready list until popped).
template <class A, class B>
class ApproximateSync {
 public:
  explicit ApproximateSync(const SyncParams& params = {}) : pairer_(params) {}

  void push_a(double stamp, A msg) {
    ops_.clear();
    if (pairer_.pushA(stamp, &ops_)) a_.emplace_back(stamp, std::move(msg));
    apply();
  }
  void push_b(double stamp, B msg) {
    ops_.clear();
    if (pairer_.pushB(stamp, &ops_)) b_.emplace_back(stamp, std::move(msg));
    apply();
  }
  /// The oldest ready pair, or nullopt.
  std::optional<SyncedPair<A, B>> pop() {
    if (ready_.empty()) return std::nullopt;
    SyncedPair<A, B> p = std::move(ready_.front());
    ready_.pop_front();
    return p;
  }
  void reset() {
    pairer_.reset();
    a_.clear();
    b_.clear();
    ready_.clear();
  }

  const SyncStats& stats() const { return pairer_.stats(); }
  bool neverPaired() const { return pairer_.neverPaired(); }
  std::size_t ready() const { return ready_.size(); }

 private:
  // The pairer only ever removes queue fronts, so the payload queues follow it.
  void apply() {
    for (StampPairer::Op op : ops_) {
      if (op == StampPairer::Op::kDropA) {
        a_.pop_front();
      } else if (op == StampPairer::Op::kDropB) {
        b_.pop_front();
      } else {
        ready_.push_back(SyncedPair<A, B>{a_.front().first, b_.front().first,
                                          std::move(a_.front().second),
                                          std::move(b_.front().second)});
        a_.pop_front();
        b_.pop_front();
      }
    }
  }

  StampPairer pairer_;
  std::vector<StampPairer::Op> ops_;
  std::deque<std::pair<double, A>> a_;
  std::deque<std::pair<double, B>> b_;
  std::deque<SyncedPair<A, B>> ready_;
};

}  // namespace hermes::agent
