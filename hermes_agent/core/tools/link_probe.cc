// hermes_link_probe: drives hermes::agent::BandwidthMonitor over a real TCP link,
// so its estimate can be compared with an independent goodput measurement (iperf3).
//   hermes_link_probe serve --port P [--bind ADDR]
//     Accepts one connection; reads messages (header: uint32 id, uint32 length, both
//     big-endian, then `length` payload bytes) and answers each whole message with a
//     4-byte ack carrying its id. Exits when the peer closes.
//   hermes_link_probe send --host H --port P --seconds S --message-bytes B
//                          [--in-flight N] [--sndbuf BYTES] [--json FILE] [--trace FILE]
//     Keeps up to N (default 4) messages outstanding for S seconds. monitor.onSend(id,
//     bytes, t) when a message starts being handed to the socket, monitor.onAck(id, t)
//     when its ack arrives (t: steady clock [s]). Prints JSON: goodput of the acked
//     bytes, the monitor's final estimate and the median of its estimates sampled
//     every 0.5 s after the first 3 s.
#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iostream>
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "hermes/agent/bandwidth_monitor.h"

using namespace hermes;

namespace {

constexpr std::uint32_t kMaxMessageBytes = 64u << 20;
constexpr double kSampleEvery_s = 0.5;
constexpr double kSampleAfter_s = 3.0;

struct Params {
  std::string mode;
  std::string host = "127.0.0.1";
  std::string bind = "0.0.0.0";
  int port = 5301;
  double seconds = 10.0;
  std::uint32_t message_bytes = 256 * 1024;
  int in_flight = 4;
  int sndbuf = 64 * 1024;
  std::string json_path, trace_path;
};

void usage() {
  std::cout <<
      "usage: hermes_link_probe serve --port P [--bind ADDR]\n"
      "       hermes_link_probe send --host H --port P --seconds S --message-bytes B\n"
      "                              [--in-flight N] [--sndbuf BYTES] [--json FILE] [--trace FILE]\n"
      "  serve: acks every whole length-prefixed message of one TCP connection.\n"
      "  send:  keeps N messages (default 4) outstanding for S seconds, feeds\n"
      "         BandwidthMonitor with send/ack times and prints goodput vs estimate (JSON).\n"
      "  --trace FILE writes one CSV line per ack: id,bytes,sent_s,ack_s,estimate_bps.\n";
}

std::string sysError(const std::string& what) { return what + ": " + std::strerror(errno); }

Expected<Params> parseArgs(int argc, char** argv) {
  Params p;
  if (argc < 2) return Error{"missing mode (serve or send); see --help"};
  p.mode = argv[1];
  if (p.mode != "serve" && p.mode != "send") return Error{"unknown mode '" + p.mode + "'"};
  for (int i = 2; i < argc; ++i) {
    const std::string a = argv[i];
    if (i + 1 >= argc) return Error{"option " + a + " needs a value"};
    const std::string v = argv[++i];
    try {
      if (a == "--host") p.host = v;
      else if (a == "--bind") p.bind = v;
      else if (a == "--port") p.port = std::stoi(v);
      else if (a == "--seconds") p.seconds = std::stod(v);
      else if (a == "--message-bytes") p.message_bytes = static_cast<std::uint32_t>(std::stoul(v));
      else if (a == "--in-flight") p.in_flight = std::stoi(v);
      else if (a == "--sndbuf") p.sndbuf = std::stoi(v);
      else if (a == "--json") p.json_path = v;
      else if (a == "--trace") p.trace_path = v;
      else return Error{"unknown option " + a};
    } catch (const std::exception&) {
      return Error{"bad value '" + v + "' for " + a};
    }
  }
  if (p.port <= 0 || p.port > 65535) return Error{"--port must be in 1..65535"};
  if (!(p.seconds > 0)) return Error{"--seconds must be > 0"};
  if (p.message_bytes == 0 || p.message_bytes > kMaxMessageBytes)
    return Error{"--message-bytes must be in 1.." + std::to_string(kMaxMessageBytes)};
  if (p.in_flight < 1) return Error{"--in-flight must be >= 1"};
  return p;
}

double now_s() {
  using namespace std::chrono;
  return duration<double>(steady_clock::now().time_since_epoch()).count();
}

/// Reads exactly n bytes; false on EOF before any byte, Error on a short read or failure.
Expected<bool> readAll(int fd, void* buf, std::size_t n) {
  auto* p = static_cast<char*>(buf);
  std::size_t got = 0;
  while (got < n) {
    const ssize_t r = ::read(fd, p + got, n - got);
    if (r < 0 && errno == EINTR) continue;
    if (r < 0) return Error{sysError("read")};
    if (r == 0) {
      if (got == 0) return false;
      return Error{"peer closed in the middle of a message"};
    }
    got += static_cast<std::size_t>(r);
  }
  return true;
}

Status writeAll(int fd, const void* buf, std::size_t n) {
  const auto* p = static_cast<const char*>(buf);
  while (n > 0) {
    const ssize_t w = ::write(fd, p, n);
    if (w < 0 && errno == EINTR) continue;
    if (w < 0) return Error{sysError("write")};
    p += w;
    n -= static_cast<std::size_t>(w);
  }
  return Status::Ok();
}

int serve(const Params& p) {
  const int ls = ::socket(AF_INET, SOCK_STREAM, 0);
  const int one = 1;
  ::setsockopt(ls, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<std::uint16_t>(p.port));
  if (::inet_pton(AF_INET, p.bind.c_str(), &addr.sin_addr) != 1) {
    std::cerr << "hermes_link_probe: --bind '" << p.bind << "' is not an IPv4 address\n";
    return 2;
  }
  const std::string where = p.bind + ":" + std::to_string(p.port);
  if (::bind(ls, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0 || ::listen(ls, 1) != 0) {
    std::cerr << "hermes_link_probe: " << sysError("listen on " + where) << "\n";
    return 1;
  }
  std::cout << "hermes_link_probe: listening on " << where << std::endl;
  const int fd = ::accept(ls, nullptr, nullptr);
  if (fd < 0) {
    std::cerr << "hermes_link_probe: " << sysError("accept on " + where) << "\n";
    return 1;
  }
  ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
  std::vector<char> payload(1 << 20);
  for (;;) {
    std::uint32_t header[2];
    auto more = readAll(fd, header, sizeof header);
    if (!more && more.error().find("peer closed") == 0) break;
    if (!more) {
      std::cerr << "hermes_link_probe: reading a header: " << more.error() << "\n";
      return 1;
    }
    if (!*more) break;  // peer closed between messages: done
    std::uint32_t left = ntohl(header[1]);
    if (left > kMaxMessageBytes) {
      std::cerr << "hermes_link_probe: message length " << left << " exceeds the limit\n";
      return 1;
    }
    while (left > 0) {
      const std::uint32_t n = std::min<std::uint32_t>(left, payload.size());
      auto r = readAll(fd, payload.data(), n);
      if (!r) {
        // The sender stops at its deadline, usually in the middle of a message.
        if (r.error().find("peer closed") == 0) return 0;
        std::cerr << "hermes_link_probe: reading a payload: " << r.error() << "\n";
        return 1;
      }
      if (!*r) return 0;
      left -= n;
    }
    if (Status s = writeAll(fd, &header[0], 4); !s) {
      std::cerr << "hermes_link_probe: sending an ack: " << s.error() << "\n";
      return 1;
    }
  }
  ::close(fd);
  ::close(ls);
  return 0;
}

Expected<int> connectTo(const Params& p) {
  const std::string where = p.host + ":" + std::to_string(p.port);
  addrinfo hints{};
  hints.ai_family = AF_INET;
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* res = nullptr;
  if (int e = ::getaddrinfo(p.host.c_str(), std::to_string(p.port).c_str(), &hints, &res); e != 0)
    return Error{"resolve " + p.host + " failed: " + ::gai_strerror(e)};
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  // A small send buffer: the kernel must not absorb seconds of data, or the
  // "handed to the socket" times would say nothing about the link.
  ::setsockopt(fd, SOL_SOCKET, SO_SNDBUF, &p.sndbuf, sizeof p.sndbuf);
  const int one = 1;
  ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
  const int rc = ::connect(fd, res->ai_addr, res->ai_addrlen);
  ::freeaddrinfo(res);
  if (rc != 0) {
    const std::string e = sysError("connect to " + where + " failed");
    ::close(fd);
    return Error{e};
  }
  ::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) | O_NONBLOCK);
  return fd;
}

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const std::size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

int send(const Params& p) {
  auto fd_or = connectTo(p);
  if (!fd_or) {
    std::cerr << "hermes_link_probe: " << fd_or.error() << "\n";
    return 1;
  }
  const int fd = *fd_or;
  std::ofstream trace;
  if (!p.trace_path.empty()) {
    trace.open(p.trace_path);
    if (!trace) {
      std::cerr << "hermes_link_probe: cannot write " << p.trace_path << "\n";
      return 1;
    }
    trace << "id,bytes,sent_s,ack_s,estimate_bps\n";
  }
  agent::BandwidthMonitor monitor;
  const std::size_t wire_bytes = p.message_bytes + 8;  // what the link carries per message
  std::vector<char> out(wire_bytes, 'h');
  std::map<std::uint32_t, double> sent_at;  // outstanding id -> send time [s]
  std::uint32_t next_id = 0;
  std::size_t out_pos = wire_bytes;  // bytes of the current message handed over
  char ack_buf[4];
  std::size_t ack_pos = 0;
  std::uint64_t bytes_acked = 0;
  std::vector<double> estimates;

  const double t0 = now_s();
  const double t_end = t0 + p.seconds;
  double next_sample = t0 + kSampleAfter_s;
  double last_ack = t0;
  for (;;) {
    const double t = now_s();
    while (t >= next_sample && next_sample <= t_end) {
      estimates.push_back(monitor.estimate(t));
      next_sample += kSampleEvery_s;
    }
    if (t >= t_end) break;
    // Start the next message once the previous one is fully handed over.
    if (out_pos == wire_bytes && static_cast<int>(sent_at.size()) < p.in_flight) {
      const std::uint32_t header[2] = {htonl(next_id), htonl(p.message_bytes)};
      std::memcpy(out.data(), header, sizeof header);
      sent_at[next_id] = t;
      monitor.onSend(next_id, wire_bytes, t);
      ++next_id;
      out_pos = 0;
    }
    pollfd pfd{fd, POLLIN, 0};
    if (out_pos < wire_bytes) pfd.events |= POLLOUT;
    const double wait_s = std::min(next_sample, t_end) - t;
    const int r = ::poll(&pfd, 1, std::max(1, static_cast<int>(wait_s * 1000.0)));
    if (r < 0 && errno == EINTR) continue;
    if (r < 0) {
      std::cerr << "hermes_link_probe: " << sysError("poll") << "\n";
      return 1;
    }
    if (pfd.revents & (POLLERR | POLLHUP)) {
      std::cerr << "hermes_link_probe: connection to " << p.host << ":" << p.port
                << " closed by the peer\n";
      return 1;
    }
    if ((pfd.revents & POLLOUT) && out_pos < wire_bytes) {
      const ssize_t w = ::write(fd, out.data() + out_pos, wire_bytes - out_pos);
      if (w < 0 && errno != EAGAIN && errno != EINTR) {
        std::cerr << "hermes_link_probe: " << sysError("write") << "\n";
        return 1;
      }
      if (w > 0) out_pos += static_cast<std::size_t>(w);
    }
    if (pfd.revents & POLLIN) {
      for (;;) {
        const ssize_t n = ::read(fd, ack_buf + ack_pos, sizeof ack_buf - ack_pos);
        if (n < 0 && (errno == EAGAIN || errno == EINTR)) break;
        if (n <= 0) {
          std::cerr << "hermes_link_probe: "
                    << (n == 0 ? std::string("server closed the connection") : sysError("read ack"))
                    << "\n";
          return 1;
        }
        ack_pos += static_cast<std::size_t>(n);
        if (ack_pos < sizeof ack_buf) continue;
        ack_pos = 0;
        std::uint32_t id;
        std::memcpy(&id, ack_buf, 4);
        id = ntohl(id);
        const double ta = now_s();
        auto it = sent_at.find(id);
        if (it == sent_at.end()) {
          std::cerr << "hermes_link_probe: ack for unknown message " << id << "\n";
          return 1;
        }
        monitor.onAck(id, ta);
        bytes_acked += wire_bytes;
        last_ack = ta;
        if (trace)
          trace << id << "," << wire_bytes << "," << it->second - t0 << "," << ta - t0 << ","
                << monitor.estimate(ta) << "\n";
        sent_at.erase(it);
      }
    }
  }
  const double elapsed = last_ack - t0;
  ::close(fd);
  nlohmann::json j;
  j["seconds"] = elapsed;
  j["bytes_acked"] = bytes_acked;
  j["messages_acked"] = next_id - sent_at.size();
  j["message_bytes"] = p.message_bytes;
  j["in_flight"] = p.in_flight;
  j["goodput_mbps"] = elapsed > 0 ? bytes_acked * 8.0 / elapsed / 1e6 : 0.0;
  j["monitor_estimate_mbps"] = monitor.estimate(last_ack) * 8.0 / 1e6;
  j["monitor_median_mbps"] = median(estimates) * 8.0 / 1e6;
  j["samples"] = estimates.size();
  j["monitor_samples"] = monitor.samples();
  const std::string text = j.dump();
  std::cout << text << std::endl;
  if (!p.json_path.empty()) {
    std::ofstream f(p.json_path);
    if (!(f << text << "\n")) {
      std::cerr << "hermes_link_probe: cannot write " << p.json_path << "\n";
      return 1;
    }
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  for (int i = 1; i < argc; ++i)
    if (std::string(argv[i]) == "--help" || std::string(argv[i]) == "-h") {
      usage();
      return 0;
    }
  auto p = parseArgs(argc, argv);
  if (!p) {
    std::cerr << "hermes_link_probe: " << p.error() << "\n";
    return 2;
  }
  return p->mode == "serve" ? serve(*p) : send(*p);
}
