#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "hermes/agent/map_buffer.h"

using namespace hermes;
using namespace hermes::agent;

namespace {
MapBufferParams params(const std::string& name) {
  MapBufferParams p;
  p.dir = ::testing::TempDir() + "/spool_" + name;
  std::filesystem::remove_all(p.dir);
  p.fsync = false;
  p.resend_timeout_s = 5.0;
  return p;
}
std::vector<std::uint8_t> frame(std::size_t n, std::uint8_t v) { return std::vector<std::uint8_t>(n, v); }
}  // namespace

TEST(MapBuffer, SurvivesRestartAndFreesAcked) {
  const auto p = params("restart");
  {
    auto b = MapBuffer::open(p);
    ASSERT_TRUE(b.ok()) << b.error();
    for (std::uint64_t s = 0; s < 5; ++s) ASSERT_TRUE(b->push(0, s, frame(1000 + s, s)));
    ASSERT_TRUE(b->ack(0, 1));
    ASSERT_TRUE(b->ack(0, 3));
    ASSERT_TRUE(b->ack(0, 3));  // duplicate ack is harmless
    EXPECT_EQ(b->pendingCount(), 3u);
  }
  auto b = MapBuffer::open(p);  // "process restart"
  ASSERT_TRUE(b.ok()) << b.error();
  EXPECT_EQ(b->pendingCount(), 3u);
  EXPECT_EQ(b->pendingBytes(), 1000u + 1002u + 1004u);
  EXPECT_EQ(b->recoveredTornBytes(), 0u);
  // Resent in order.
  std::vector<std::uint64_t> order;
  while (auto* s = b->nextToSend(0.0)) {
    order.push_back(s->seq);
    EXPECT_EQ(s->frame, frame(1000 + s->seq, s->seq));
    b->markSent(s->session, s->seq, 0.0);
  }
  EXPECT_EQ(order, (std::vector<std::uint64_t>{0, 2, 4}));
  EXPECT_EQ(b->nextToSend(4.9), nullptr);
  ASSERT_NE(b->nextToSend(5.0), nullptr);  // resend timeout
  EXPECT_EQ(b->nextToSend(5.0)->seq, 0u);
  // Each resend doubles the wait (at most x8): 5, then 10, 20, 40, 40 s.
  double t = 5.0;
  for (double wait : {10.0, 20.0, 40.0, 40.0}) {
    b->markSent(0, 0, t);
    b->markSent(0, 2, t);
    b->markSent(0, 4, t);
    EXPECT_EQ(b->nextToSend(t + wait - 0.1), nullptr) << "wait " << wait;
    ASSERT_NE(b->nextToSend(t + wait), nullptr) << "wait " << wait;
    t += wait;
  }
  // A reconnect resends at once.
  b->resetSendTimes();
  EXPECT_NE(b->nextToSend(t), nullptr);
}

TEST(MapBuffer, TornTailIsCutAndReported) {
  const auto p = params("torn");
  {
    auto b = MapBuffer::open(p);
    ASSERT_TRUE(b.ok());
    ASSERT_TRUE(b->push(0, 0, frame(500, 1)));
    ASSERT_TRUE(b->push(0, 1, frame(500, 2)));
  }
  const std::string file = p.dir + "/spool.bin";
  const auto size = std::filesystem::file_size(file);
  std::filesystem::resize_file(file, size - 100);  // crash in the middle of record 2
  {
    auto b = MapBuffer::open(p);
    ASSERT_TRUE(b.ok()) << b.error();
    EXPECT_EQ(b->pendingCount(), 1u);
    EXPECT_GT(b->recoveredTornBytes(), 0u);
    ASSERT_TRUE(b->push(0, 1, frame(500, 2)));  // re-pushed after the crash
  }
  auto b = MapBuffer::open(p);
  ASSERT_TRUE(b.ok());
  EXPECT_EQ(b->pendingCount(), 2u);
  EXPECT_EQ(b->recoveredTornBytes(), 0u);
}

TEST(MapBuffer, CapRefusesNewAndKeepsOld) {
  auto p = params("cap");
  p.max_mbytes = 0.01;  // 10 kB
  auto b = MapBuffer::open(p);
  ASSERT_TRUE(b.ok());
  for (std::uint64_t s = 0; s < 4; ++s) ASSERT_TRUE(b->push(0, s, frame(2400, 7)));
  Status full = b->push(0, 4, frame(2400, 7));
  ASSERT_FALSE(full.ok());
  EXPECT_NE(full.error().find("full"), std::string::npos);
  EXPECT_EQ(b->pendingCount(), 4u);
  EXPECT_FALSE(b->push(0, 3, frame(10, 1)).ok());  // duplicate key
  ASSERT_TRUE(b->ack(0, 0));
  EXPECT_TRUE(b->push(0, 4, frame(2400, 7)).ok());
}

TEST(MapBuffer, CompactionKeepsPendingAndShrinksFile) {
  const auto p = params("compact");
  auto b = MapBuffer::open(p);
  ASSERT_TRUE(b.ok());
  for (std::uint64_t s = 0; s < 40; ++s) {
    ASSERT_TRUE(b->push(0, s, frame(100000, s & 0xff)));
    if (s >= 2) {
      ASSERT_TRUE(b->ack(0, s - 2));
    }
  }
  EXPECT_EQ(b->pendingCount(), 2u);
  // 4 MB were written; compaction keeps the file near the pending bytes
  // (threshold: 2 x pending + 1 MiB slack, plus at most one record).
  EXPECT_LT(b->fileBytes(), 2u * 200100u + (1u << 20) + 100100u);
  auto again = MapBuffer::open(p);
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(again->pendingCount(), 2u);
}

TEST(MapBuffer, SessionsIncreaseAcrossRestarts) {
  const auto p = params("session");
  std::uint32_t first, second;
  {
    auto b = MapBuffer::open(p);
    ASSERT_TRUE(b.ok());
    first = *b->newSession();
    ASSERT_TRUE(b->push(first + 5, 0, frame(10, 1)));  // pending from a later session
  }
  auto b = MapBuffer::open(p);
  second = *b->newSession();
  EXPECT_GT(second, first + 5);
}

// clear_spool used to delete the whole spool folder, session counter included: the
// restarted agent began at session 0 again and the server, which had seen (0, 0..n) from
// the previous run, acknowledged the new submaps as duplicates and never applied them.
TEST(MapBuffer, DiscardPendingDropsBacklogButKeepsSessionsIncreasing) {
  const auto p = params("discard");
  std::uint32_t first;
  {
    auto b = MapBuffer::open(p);
    ASSERT_TRUE(b.ok());
    first = *b->newSession();
    for (std::uint64_t s = 0; s < 3; ++s) ASSERT_TRUE(b->push(first, s, frame(100, 1)));
    ASSERT_TRUE(b->ack(first, 0));
    ASSERT_TRUE(b->push(first + 3, 0, frame(100, 2)));  // pending from a later session
  }
  {
    auto b = MapBuffer::open(p);  // restart with "clear the backlog"
    ASSERT_TRUE(b.ok());
    auto dropped = b->discardPending();
    ASSERT_TRUE(dropped.ok()) << dropped.error();
    EXPECT_EQ(*dropped, 3u);
    EXPECT_EQ(b->pendingCount(), 0u);
    EXPECT_EQ(b->pendingBytes(), 0u);
    EXPECT_EQ(b->nextToSend(0.0), nullptr);
  }
  auto b = MapBuffer::open(p);
  ASSERT_TRUE(b.ok());
  EXPECT_EQ(b->pendingCount(), 0u);  // the file was rewritten empty
  const std::uint32_t next = *b->newSession();
  EXPECT_GT(next, first + 3) << "a session of the discarded backlog would be reused";
  EXPECT_TRUE(b->push(next, 0, frame(10, 3)));
  auto empty = b->discardPending();  // nothing pending but the new one
  ASSERT_TRUE(empty.ok());
  EXPECT_EQ(*empty, 1u);
  EXPECT_GT(*b->newSession(), next);
}

TEST(MapBuffer, BadParamsNameTheKey) {
  MapBufferParams p;
  auto b = MapBuffer::open(p);
  ASSERT_FALSE(b.ok());
  EXPECT_NE(b.error().find("uplink.buffer.dir"), std::string::npos);
}
