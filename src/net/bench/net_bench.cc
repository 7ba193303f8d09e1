// teachsim bench net: round trip of a small control message (client -> server -> reply) over
// loopback WebSocket, against the peer "raw TCP ping-pong of the same bytes" in the same run
// (the floor any protocol stack on this machine sits on), and camera-frame throughput.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <thread>
#include <vector>

#include "teachsim/base/bench_registry.h"
#include "teachsim/base/json.h"
#include "teachsim/net/client.h"
#include "teachsim/net/server.h"

namespace teachsim::net {
namespace {

using Clock = std::chrono::steady_clock;
using json::Json;

struct Stats {
  double median_us = 0, p99_us = 0;
};

Stats Summarise(std::vector<double> us) {
  std::sort(us.begin(), us.end());
  if (us.empty()) return {};
  return {us[us.size() / 2], us[std::min(us.size() - 1, us.size() * 99 / 100)]};
}

class Echo : public ServerHandler {
 public:
  void OnMessage(Server& server, SessionId id, const Message& m) override {
    if (m.type == MessageType::kConsoleCommand) {
      (void)server.Send(id, MessageType::kConsoleOutput, {{"text", m.body["line"]}, {"ok", true}, {"in_reply_to", m.seq}});
    }
  }
};

class Counter : public ClientHandler {
 public:
  void OnMessage(Client&, const Message& m) override {
    if (m.type == MessageType::kConsoleOutput) ++replies;
  }
  void OnFrame(Client&, const BinaryFrame&) override { ++frames; }
  std::size_t replies = 0;
  std::atomic<std::size_t> frames{0};
};

// The peer: a TCP echo on loopback, same payload size, TCP_NODELAY, blocking sockets.
Stats RawTcpPingPong(std::size_t bytes, int count) {
  int listener = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t len = sizeof addr;
  if (::bind(listener, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0 || ::listen(listener, 1) != 0 ||
      ::getsockname(listener, reinterpret_cast<sockaddr*>(&addr), &len) != 0) {
    ::close(listener);
    return {};
  }
  auto exact = [](int fd, char* data, std::size_t n, bool write) {
    std::size_t done = 0;
    while (done < n) {
      ssize_t r = write ? ::send(fd, data + done, n - done, MSG_NOSIGNAL) : ::recv(fd, data + done, n - done, 0);
      if (r <= 0) return false;
      done += static_cast<std::size_t>(r);
    }
    return true;
  };
  std::thread echo([&] {
    int fd = ::accept(listener, nullptr, nullptr);
    int one = 1;
    ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    std::vector<char> buffer(bytes);
    while (exact(fd, buffer.data(), bytes, false) && exact(fd, buffer.data(), bytes, true)) {
    }
    ::close(fd);
  });
  int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  int one = 1;
  ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
  std::vector<double> us;
  if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0) {
    std::vector<char> buffer(bytes, 'x');
    for (int i = 0; i < count; ++i) {
      auto t0 = Clock::now();
      if (!exact(fd, buffer.data(), bytes, true) || !exact(fd, buffer.data(), bytes, false)) break;
      us.push_back(std::chrono::duration<double, std::micro>(Clock::now() - t0).count());
    }
  }
  ::close(fd);
  echo.join();
  ::close(listener);
  return Summarise(us);
}

int Run(const BenchArgs& args) {
  const int count = args.quick ? 200 : 3000;
  const double frame_seconds = args.quick ? 0.2 : 2.0;
  SteadyClock clock;

  // The server on its own thread, as in another process; the client on this one.
  EventLoop server_loop;
  Echo echo;
  Server server(server_loop, clock, ServerOptions{}, echo);
  Status started = server.Start();
  if (!started.ok()) {
    std::fprintf(stderr, "bench net: %s\n", started.message().c_str());
    return 1;
  }
  std::vector<double> ws_us;
  std::size_t message_bytes = 0;
  double frames_per_s = 0, frame_mib_per_s = 0;
  {
    LoopThread server_thread(server_loop);
    EventLoop loop;
    Counter counter;
    ClientOptions co;
    co.port = server.port();
    Client client(loop, clock, co, counter);
    client.Connect();
    if (!loop.RunUntil([&] { return client.session().has_value(); }, std::chrono::seconds(5))) {
      std::fprintf(stderr, "bench net: cannot connect\n");
      return 1;
    }
    const std::string line = "select cube45";
    message_bytes = Serialize(MakeMessage(MessageType::kConsoleCommand, 100, {{"line", line}})).size();
    for (int i = 0; i < count; ++i) {
      std::size_t before = counter.replies;
      auto t0 = Clock::now();
      if (!client.Send(MessageType::kConsoleCommand, {{"line", line}}).ok()) break;
      if (!loop.RunUntil([&] { return counter.replies > before; }, std::chrono::seconds(5))) break;
      ws_us.push_back(std::chrono::duration<double, std::micro>(Clock::now() - t0).count());
    }
    // Camera frames, 640x480 gray8, as fast as the server can send them.
    std::vector<std::uint8_t> pixels(640 * 480, 128);
    BinaryHeader header;
    header.width = 640;
    header.height = 480;
    std::atomic<bool> sending{true};
    std::size_t frames_before = counter.frames;
    std::size_t sent = frames_before;
    auto t0 = Clock::now();
    std::function<void()> send_one;
    send_one = [&] {
      if (!sending) return;
      // At most 4 frames in flight: measures delivery, not how fast a queue fills.
      if (sent < counter.frames + 4) {
        for (SessionId id : server.Sessions()) sent += server.SendFrame(id, header, pixels).ok() ? 1 : 0;
      }
      server_loop.Post(send_one);
    };
    server_loop.Post(send_one);
    loop.RunFor(std::chrono::duration_cast<Duration>(std::chrono::duration<double>(frame_seconds)));
    double elapsed = std::chrono::duration<double>(Clock::now() - t0).count();
    sending = false;
    frames_per_s = static_cast<double>(counter.frames - frames_before) / elapsed;
    frame_mib_per_s = frames_per_s * (pixels.size() + kBinaryHeaderBytes) / (1 << 20);
    server_loop.Post([&] { server.Stop(); });
    loop.RunFor(std::chrono::milliseconds(50));
  }
  Stats ws = Summarise(ws_us);
  Stats tcp = RawTcpPingPong(message_bytes, count);
  Json out = {{"benchmark", "net"},
              {"round_trips", ws_us.size()},
              {"message_bytes", message_bytes},
              {"websocket_rtt_median_us", ws.median_us},
              {"websocket_rtt_p99_us", ws.p99_us},
              {"raw_tcp_rtt_median_us", tcp.median_us},
              {"raw_tcp_rtt_p99_us", tcp.p99_us},
              {"camera_frames_per_s_640x480_gray8", frames_per_s},
              {"camera_mib_per_s", frame_mib_per_s}};
  if (args.json) {
    std::printf("%s\n", out.dump(2).c_str());
  } else {
    std::printf("round trip of a %zu-byte message over loopback (%zu samples)\n", message_bytes, ws_us.size());
    std::printf("  teachsim WebSocket  median %8.1f us   p99 %8.1f us\n", ws.median_us, ws.p99_us);
    std::printf("  raw TCP ping-pong   median %8.1f us   p99 %8.1f us   (peer: the floor)\n", tcp.median_us, tcp.p99_us);
    std::printf("camera frames 640x480 gray8: %.0f frames/s (%.0f MiB/s)\n", frames_per_s, frame_mib_per_s);
  }
  return ws_us.size() == static_cast<std::size_t>(count) ? 0 : 1;
}

}  // namespace

TEACHSIM_BENCH("net", "loopback WebSocket round trip against raw TCP ping-pong; camera-frame throughput", Run);

}  // namespace teachsim::net
