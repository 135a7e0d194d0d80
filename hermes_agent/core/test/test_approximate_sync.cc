#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "hermes/agent/approximate_sync.h"

using namespace hermes::agent;

namespace {

using Sync = ApproximateSync<int, int>;

struct Msg {
  double t;
  bool is_a;
  int id;
};

// Pushes messages in stamp order (A first on equal stamps), popping after each push.
std::vector<SyncedPair<int, int>> run(Sync* sync, std::vector<Msg> msgs) {
  std::stable_sort(msgs.begin(), msgs.end(), [](const Msg& x, const Msg& y) {
    return x.t < y.t || (x.t == y.t && x.is_a && !y.is_a);
  });
  std::vector<SyncedPair<int, int>> out;
  for (const Msg& m : msgs) {
    if (m.is_a)
      sync->push_a(m.t, m.id);
    else
      sync->push_b(m.t, m.id);
    while (auto p = sync->pop()) out.push_back(*p);
  }
  return out;
}

void expectTimeOrdered(const std::vector<SyncedPair<int, int>>& pairs, double slop) {
  for (std::size_t i = 0; i < pairs.size(); ++i) {
    EXPECT_LE(std::abs(pairs[i].stamp_a - pairs[i].stamp_b), slop + 1e-12);
    if (i > 0) {
      EXPECT_GT(pairs[i].stamp_a, pairs[i - 1].stamp_a);
      EXPECT_GT(pairs[i].stamp_b, pairs[i - 1].stamp_b);
    }
  }
}

}  // namespace

TEST(ApproximateSync, IdenticalStampsPairExactly) {
  SyncParams p;
  p.slop = 0.001;
  Sync sync(p);
  for (int i = 0; i < 50; ++i) {
    const double t = 100.0 + 0.05 * i;
    if (i % 2) {  // either stream may come first
      sync.push_b(t, 1000 + i);
      EXPECT_FALSE(sync.pop());
      sync.push_a(t, i);
    } else {
      sync.push_a(t, i);
      EXPECT_FALSE(sync.pop());
      sync.push_b(t, 1000 + i);
    }
    auto pair = sync.pop();
    ASSERT_TRUE(pair) << i;
    EXPECT_EQ(pair->a, i);
    EXPECT_EQ(pair->b, 1000 + i);
    EXPECT_EQ(pair->stamp_a, t);
    EXPECT_EQ(pair->stamp_b, t);
    EXPECT_FALSE(sync.pop());
  }
  EXPECT_EQ(sync.stats().paired, 50);
  EXPECT_EQ(sync.stats().dropped_a + sync.stats().dropped_b + sync.stats().out_of_order, 0);
  EXPECT_FALSE(sync.neverPaired());
}

TEST(ApproximateSync, JitteredTumLikeStreamsPairByIndex) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> offset(-0.015, 0.015);
  std::vector<Msg> msgs;
  const int n = 300;
  for (int i = 0; i < n; ++i) {
    const double t = 1305031102.0 + i / 30.0;
    msgs.push_back({t, true, i});
    msgs.push_back({t + offset(rng), false, i});
  }
  Sync sync;  // slop 0.020
  const auto pairs = run(&sync, msgs);
  ASSERT_GE(int(pairs.size()), n - 1);  // the last colour may wait for a later depth
  for (const auto& pr : pairs) EXPECT_EQ(pr.a, pr.b);
  expectTimeOrdered(pairs, 0.020);
  EXPECT_EQ(sync.stats().dropped_a, 0);
  EXPECT_EQ(sync.stats().dropped_b, 0);
  EXPECT_EQ(sync.stats().received_a, n);
}

TEST(ApproximateSync, EarlyDepthIsNotHeldBackOnceTheRhythmIsKnown) {
  // 30 Hz depth stamped 10 ms before its colour image, each message pushed as
  // it arrives. Once B's rhythm is known (8 intervals), a colour image pairs at
  // once: the next depth (23 ms after the colour) cannot be closer than this
  // one (10 ms before). Before that the pair waits for the next depth.
  Sync sync;  // slop 0.020
  for (int k = 0; k < 30; ++k) {
    const double t = 100.0 + k / 30.0;
    sync.push_b(t - 0.010, k);
    if (k > 0 && k <= 8) {  // the previous colour image paired only now
      auto late = sync.pop();
      ASSERT_TRUE(late.has_value()) << k;
      EXPECT_EQ(late->a, k - 1);
      EXPECT_EQ(late->b, k - 1);
    }
    sync.push_a(t, k);
    auto p = sync.pop();
    if (k < 8) {
      EXPECT_FALSE(p.has_value()) << "k " << k << ": rhythm unknown, must wait";
      continue;
    }
    ASSERT_TRUE(p.has_value()) << "k " << k << ": paired without waiting";
    EXPECT_EQ(p->a, k);
    EXPECT_EQ(p->b, k);
  }
  EXPECT_EQ(sync.stats().paired, 30);
  EXPECT_EQ(sync.stats().dropped_a + sync.stats().dropped_b, 0);

  // A depth stream faster than its rhythm suggested may still pair a farther
  // depth, but never one beyond the slop, and pairs stay in time order.
  Sync jumpy;
  std::vector<SyncedPair<int, int>> pairs;
  double tb = 200.0;
  for (int k = 0; k < 40; ++k) {
    const double ta = 200.0 + k / 30.0;
    tb = k < 20 ? ta - 0.012 : tb + 0.017;  // depth doubles its rate halfway
    jumpy.push_b(tb, k);
    if (k >= 20) jumpy.push_b(tb += 0.017, 100 + k);
    jumpy.push_a(ta, k);
    while (auto p = jumpy.pop()) pairs.push_back(*p);
  }
  EXPECT_GE(pairs.size(), 35u);
  expectTimeOrdered(pairs, 0.020);
}

TEST(ApproximateSync, ClosestPartnerWinsAndOlderOnesAreDropped) {
  Sync sync;
  sync.push_a(1.000, 1);
  sync.push_b(0.990, 10);  // within slop, but a later depth may be closer
  EXPECT_FALSE(sync.pop());
  sync.push_b(1.005, 11);
  auto p = sync.pop();
  ASSERT_TRUE(p);
  EXPECT_EQ(p->a, 1);
  EXPECT_EQ(p->b, 11);
  EXPECT_EQ(sync.stats().dropped_b, 1);  // 0.990 is older than the paired depth
}

TEST(ApproximateSync, UnmatchedMessagesAreDropped) {
  std::vector<Msg> msgs;
  for (int i = 0; i < 20; ++i) {
    const double t = 10.0 + i / 30.0;
    if (i != 9) msgs.push_back({t, true, i});                               // colour 9 lost
    if (i != 5 && i != 6 && i != 12) msgs.push_back({t + 0.005, false, i});  // depth lost
  }
  Sync sync;
  const auto pairs = run(&sync, msgs);
  EXPECT_EQ(pairs.size(), 16u);
  for (const auto& pr : pairs) EXPECT_EQ(pr.a, pr.b);
  expectTimeOrdered(pairs, 0.020);
  EXPECT_EQ(sync.stats().dropped_a, 3);  // colour 5, 6, 12
  EXPECT_EQ(sync.stats().dropped_b, 1);  // depth 9
  EXPECT_EQ(sync.stats().paired, 16);
}

TEST(ApproximateSync, FullQueueDropsTheOldest) {
  SyncParams p;
  p.capacity = 3;
  Sync sync(p);
  for (int i = 0; i < 5; ++i) sync.push_a(1.0 + 0.1 * i, i);  // no depth yet
  EXPECT_EQ(sync.stats().overflow_a, 2);
  EXPECT_EQ(sync.stats().dropped_a, 2);
  sync.push_b(1.2, 102);  // pairs with A 2, the oldest one kept
  auto pr = sync.pop();
  ASSERT_TRUE(pr);
  EXPECT_EQ(pr->a, 2);
  EXPECT_EQ(pr->b, 102);
  // The same on stream B.
  Sync other(p);
  for (int i = 0; i < 4; ++i) other.push_b(5.0 + 0.001 * i, i);
  EXPECT_EQ(other.stats().overflow_b, 1);
  other.push_a(5.001, 7);
  pr = other.pop();
  ASSERT_TRUE(pr);
  EXPECT_EQ(pr->b, 1);
}

TEST(ApproximateSync, OutOfOrderMessagesAreDropped) {
  Sync sync;
  sync.push_a(2.0, 1);
  sync.push_b(2.0, 1);
  ASSERT_TRUE(sync.pop());
  sync.push_a(1.5, 2);   // before the last popped
  sync.push_a(2.0, 3);   // repeated stamp
  sync.push_b(std::numeric_limits<double>::quiet_NaN(), 4);
  EXPECT_EQ(sync.stats().out_of_order, 3);
  EXPECT_FALSE(sync.pop());
  sync.push_a(2.1, 5);
  sync.push_b(2.1, 5);
  auto p = sync.pop();
  ASSERT_TRUE(p);
  EXPECT_EQ(p->a, 5);
  EXPECT_EQ(sync.stats().received_a, 4);
  // After reset() (e.g. a bag restarting) earlier stamps are accepted again.
  sync.reset();
  sync.push_a(1.0, 6);
  sync.push_b(1.0, 6);
  EXPECT_TRUE(sync.pop());
  EXPECT_EQ(sync.stats().out_of_order, 3);
}

TEST(ApproximateSync, ConstantOffsetBeyondSlopNeverPairs) {
  SyncParams p;
  p.slop = 0.001;
  Sync sync(p);
  for (int i = 0; i < 30; ++i) {
    EXPECT_FALSE(sync.neverPaired()) << i;
    const double t = 12.0001 + 0.05 * i;
    sync.push_a(t, i);
    sync.push_b(t + 0.0133, i);
    EXPECT_FALSE(sync.pop());
  }
  EXPECT_TRUE(sync.neverPaired());
  EXPECT_EQ(sync.stats().paired, 0);
  EXPECT_GE(sync.stats().dropped_a, 29);
  EXPECT_GE(sync.stats().dropped_b, 29);
  EXPECT_EQ(sync.stats().overflow_a + sync.stats().overflow_b, 0);
  EXPECT_NEAR(sync.stats().newest_b - sync.stats().newest_a, 0.0133, 1e-9);
  EXPECT_NE(sync.stats().summary().find("paired 0"), std::string::npos);
}

TEST(ApproximateSync, ParamsValidate) {
  SyncParams p;
  EXPECT_TRUE(p.validate());
  p.slop = -0.1;
  EXPECT_FALSE(p.validate());
  p = SyncParams{};
  p.capacity = 0;
  EXPECT_NE(p.validate().error().find("capacity"), std::string::npos);
}
