#include "hermes/agent/approximate_sync.h"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace hermes::agent {

Status SyncParams::validate() const {
  if (!(slop >= 0 && std::isfinite(slop)))
    return Error{"sync slop must be a finite number >= 0 [s], got " + std::to_string(slop)};
  if (capacity < 1) return Error{"sync capacity must be >= 1, got " + std::to_string(capacity)};
  if (never_paired_after < 1)
    return Error{"sync never_paired_after must be >= 1, got " + std::to_string(never_paired_after)};
  return Status::Ok();
}

std::string SyncStats::summary() const {
  std::ostringstream o;
  o << "paired " << paired << ", dropped A " << dropped_a << " (overflow " << overflow_a
    << "), dropped B " << dropped_b << " (overflow " << overflow_b << "), out of order "
    << out_of_order;
  return o.str();
}

StampPairer::StampPairer(const SyncParams& params) : params_(params) {
  const Status s = params.validate();
  HERMES_CHECK(s.ok(), s.error());
}

void StampPairer::reset() {
  a_.clear();
  b_.clear();
  b_gaps_.clear();
  have_a_ = have_b_ = false;
}

bool StampPairer::neverPaired() const {
  return stats_.paired == 0 && stats_.received_a >= params_.never_paired_after &&
         stats_.received_b >= params_.never_paired_after;
}

void StampPairer::dropA(std::vector<Op>* ops) {
  a_.pop_front();
  ++stats_.dropped_a;
  ops->push_back(Op::kDropA);
}

void StampPairer::dropB(std::vector<Op>* ops) {
  b_.pop_front();
  ++stats_.dropped_b;
  ops->push_back(Op::kDropB);
}

bool StampPairer::push(bool is_a, double stamp, std::vector<Op>* ops) {
  (is_a ? stats_.received_a : stats_.received_b)++;
  const bool have = is_a ? have_a_ : have_b_;
  double& newest = is_a ? stats_.newest_a : stats_.newest_b;
  if (!std::isfinite(stamp) || (have && !(stamp > newest))) {
    ++stats_.out_of_order;
    return false;
  }
  if (!is_a && have) {  // the B stream's rhythm: its last kRhythmGaps intervals
    b_gaps_.push_back(stamp - newest);
    if (int(b_gaps_.size()) > kRhythmGaps) b_gaps_.pop_front();
  }
  newest = stamp;
  (is_a ? have_a_ : have_b_) = true;
  std::deque<double>& q = is_a ? a_ : b_;
  if (int(q.size()) >= params_.capacity) {
    if (is_a) {
      ++stats_.overflow_a;
      dropA(ops);
    } else {
      ++stats_.overflow_b;
      dropB(ops);
    }
  }
  q.push_back(stamp);
  match(ops);
  return true;
}

double StampPairer::minGapB() const {
  if (int(b_gaps_.size()) < kRhythmGaps) return std::numeric_limits<double>::quiet_NaN();
  return *std::min_element(b_gaps_.begin(), b_gaps_.end());
}

bool StampPairer::nextBIsFarther(double ta) const {
  const double gap = minGapB();
  if (!(gap > 0)) return false;  // rhythm unknown yet
  const double newest = b_.back();
  return newest + kRhythmMargin * gap - ta >= ta - newest;
}

void StampPairer::match(std::vector<Op>* ops) {
  const double slop = params_.slop;
  while (!a_.empty()) {
    const double ta = a_.front();
    // B's before ta - slop: every waiting or future A is at or after ta.
    while (!b_.empty() && ta - b_.front() > slop) dropB(ops);
    // The closest waiting B within slop (ties: the older one).
    int best = -1;
    for (std::size_t i = 0; i < b_.size() && b_[i] - ta <= slop; ++i)
      if (best < 0 || std::abs(b_[i] - ta) < std::abs(b_[best] - ta)) best = int(i);
    if (best < 0) {
      // Later B's come after newest_b: if that is past ta + slop, A never pairs.
      if (have_b_ && stats_.newest_b - ta > slop) {
        dropA(ops);
        continue;
      }
      break;  // wait for B
    }
    // b_ is not empty, so b_.back() is the newest B. A later B could still be
    // closer while the newest B is before ta -- unless the B stream's rhythm
    // says the next one comes too late to be closer.
    if (b_.back() < ta && !nextBIsFarther(ta)) break;
    for (int i = 0; i < best; ++i) dropB(ops);
    a_.pop_front();
    b_.pop_front();
    ++stats_.paired;
    ops->push_back(Op::kPair);
  }
  // No A waits: B's more than slop before the newest A can pair with no later A.
  if (a_.empty() && have_a_)
    while (!b_.empty() && stats_.newest_a - b_.front() > slop) dropB(ops);
}

}  // namespace hermes::agent
