// Exactly-once delivery through an emulated lossy link with an outage and an
// agent process restart in the middle (issue: uplink, in-process part).
#include <gtest/gtest.h>

#include <filesystem>
#include <memory>
#include <set>

#include "hermes/agent/uplink_sender.h"
#include "hermes/core/emulated_link.h"

using namespace hermes;
using namespace hermes::agent;

namespace {
struct Receiver {  // minimal server side: dedup by (session, seq), ack everything
  std::set<std::pair<std::uint32_t, std::uint64_t>> applied;
  int duplicates = 0;
  bool receive(std::uint32_t session, std::uint64_t seq) {
    if (!applied.insert({session, seq}).second) ++duplicates;
    return true;
  }
};

std::uint64_t key(std::uint32_t session, std::uint64_t seq) { return (std::uint64_t{session} << 40) | seq; }
}  // namespace

TEST(UplinkDelivery, ExactlyOnceThroughLossOutageAndRestart) {
  auto trace = LinkTrace::fromString(
      "time_s,rate_mbitps,latency_ms,loss\n0,10,20,0.2\n100,0,20,0\n130,10,20,0.2\n", "trace");
  ASSERT_TRUE(trace.ok());
  SharedLink link(*trace, 1, 11);
  Receiver server;

  UplinkParams p;
  p.buffer.dir = ::testing::TempDir() + "/uplink_delivery";
  std::filesystem::remove_all(p.buffer.dir);
  p.buffer.fsync = false;
  p.buffer.resend_timeout_s = 4.0;
  p.buffer.max_mbytes = 20.0;

  // The "wire": frames travel over the link; the message id packs (session, seq).
  auto makeSender = [&]() {
    auto s = UplinkSender::create(p, [&](std::uint32_t session, std::uint64_t seq,
                                         const std::vector<std::uint8_t>& frame) {
      LinkMessage m;
      m.id = key(session, seq);
      m.bytes = frame.size();
      link.send(m, link.now());
    });
    EXPECT_TRUE(s.ok()) << s.error();
    return std::make_unique<UplinkSender>(std::move(*s));
  };

  auto agent = makeSender();
  std::uint32_t session = *agent->buffer().newSession();
  std::uint64_t seq = 0;
  std::set<std::pair<std::uint32_t, std::uint64_t>> submitted;
  std::vector<std::pair<double, std::pair<std::uint32_t, std::uint64_t>>> acks_in_flight;
  std::size_t max_spool = 0;

  for (int step = 0; step <= 4000; ++step) {  // 0.05 s steps, 200 s
    const double t = step * 0.05;
    if (step == 1500) {  // t = 75 s: the agent process is killed and restarted
      agent.reset();
      acks_in_flight.clear();  // acks for the dead process are lost with it
      agent = makeSender();
      session = *agent->buffer().newSession();  // fresh map -> new session
      seq = 0;
    }
    if (step % 100 == 0 && t < 160) {  // a 60-kB submap every 5 s
      ASSERT_TRUE(agent->submit(session, seq, std::vector<std::uint8_t>(60000, 1), t));
      submitted.insert({session, seq});
      ++seq;
    }
    for (const auto& d : link.advanceTo(t)) {
      if (d.lost) continue;
      const std::uint32_t s = static_cast<std::uint32_t>(d.message.id >> 40);
      const std::uint64_t q = d.message.id & ((std::uint64_t{1} << 40) - 1);
      server.receive(s, q);
      const double ack_at = link.ackArrival(d.arrival_time);
      if (ack_at >= 0) acks_in_flight.push_back({ack_at, {s, q}});
    }
    for (auto it = acks_in_flight.begin(); it != acks_in_flight.end();) {
      if (it->first <= t) {
        ASSERT_TRUE(agent->onAck(it->second.first, it->second.second, t));
        it = acks_in_flight.erase(it);
      } else {
        ++it;
      }
    }
    agent->poll(t);
    max_spool = std::max(max_spool, agent->buffer().pendingBytes());
  }
  EXPECT_EQ(server.applied, submitted);  // none lost
  EXPECT_EQ(agent->buffer().pendingCount(), 0u);
  EXPECT_LT(static_cast<double>(max_spool), p.buffer.max_mbytes * 1e6);
  EXPECT_GT(agent->stats().resends + server.duplicates, 0u);  // loss really happened
  std::printf("submitted %zu, applied %zu, duplicates dropped %d, max spool %zu B\n",
              submitted.size(), server.applied.size(), server.duplicates, max_spool);
}

// The first message is lost before any acknowledgement. The monitor's overdue cap
// (bytes / time in transfer) grows the resend wait as fast as time passes (on a
// slow link that is right: resending into it only congests it), so the resend
// comes from the outage rule: silence beyond the transfer time at 1 % of the start
// guess plus the outage timeout. Bounded, if slow (documented in the README).
TEST(UplinkDelivery, LostFirstMessageIsResentByTheOutageRule) {
  UplinkParams p;
  p.buffer.dir = ::testing::TempDir() + "/uplink_first_lost";
  std::filesystem::remove_all(p.buffer.dir);
  p.buffer.fsync = false;
  p.buffer.resend_timeout_s = 3.0;
  int sends = 0;
  auto s = UplinkSender::create(p, [&](std::uint32_t, std::uint64_t, const std::vector<std::uint8_t>&) {
    ++sends;  // every send is lost: no ack ever comes
  });
  ASSERT_TRUE(s.ok()) << s.error();
  const std::uint32_t session = *s->buffer().newSession();
  const std::size_t bytes = 50000;
  ASSERT_TRUE(s->submit(session, 0, std::vector<std::uint8_t>(bytes, 7), 0.0));
  ASSERT_EQ(sends, 1);
  const double bound = bytes / (0.01 * p.monitor.initial_bps) + p.monitor.outage_timeout_s;
  double resent_at = -1;
  for (double t = 0.1; t < 2 * bound && resent_at < 0; t += 0.1) {
    s->poll(t);
    if (sends > 1) resent_at = t;
  }
  ASSERT_GT(resent_at, 0) << "never resent";
  EXPECT_LE(resent_at, bound + 0.2);
  EXPECT_GT(resent_at, p.buffer.resend_timeout_s + 2.0);  // not into a link that may be slow
}
