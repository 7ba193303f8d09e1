// Helpers for the loopback tests: recording handlers and a raw HTTP client on POSIX sockets (so
// requests can be malformed on purpose). Only 127.0.0.1, ephemeral ports, and timeouts everywhere.
#pragma once

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>

#include <chrono>
#include <future>
#include <string>
#include <vector>

#include "teachsim/net/client.h"
#include "teachsim/net/server.h"

namespace teachsim::net::testing {

using namespace std::chrono_literals;

struct ServerRecorder : ServerHandler {
  std::vector<SessionId> opened, closed;
  std::vector<std::pair<SessionId, Message>> messages;
  std::vector<std::pair<SessionId, BinaryFrame>> frames;
  std::vector<std::pair<SessionId, LinkEvent>> link_events;
  std::vector<std::optional<SessionId>> lease_changes;
  std::vector<std::string> close_reasons;
  std::function<void(Server&, SessionId, const Message&)> on_message;

  void OnOpen(Server&, SessionId id) override { opened.push_back(id); }
  void OnMessage(Server& server, SessionId id, const Message& m) override {
    messages.emplace_back(id, m);
    if (on_message) on_message(server, id, m);
  }
  void OnFrame(Server&, SessionId id, const BinaryFrame& f) override { frames.emplace_back(id, f); }
  void OnClose(Server&, SessionId id, const std::string& reason) override {
    closed.push_back(id);
    close_reasons.push_back(reason);
  }
  void OnLinkEvent(Server&, SessionId id, const LinkEvent& e) override { link_events.emplace_back(id, e); }
  void OnLeaseChanged(Server&, std::optional<SessionId> holder) override { lease_changes.push_back(holder); }

  std::size_t CountLinks(SessionId id, LinkEvent::Kind kind) const {
    std::size_t n = 0;
    for (const auto& [s, e] : link_events) n += (s == id && e.kind == kind) ? 1 : 0;
    return n;
  }
};

struct ClientRecorder : ClientHandler {
  int opens = 0;
  std::vector<Message> messages;
  std::vector<BinaryFrame> frames;
  std::vector<Status> closes;
  std::vector<LinkEvent> link_events;

  void OnOpen(Client&) override { ++opens; }
  void OnMessage(Client&, const Message& m) override { messages.push_back(m); }
  void OnFrame(Client&, const BinaryFrame& f) override { frames.push_back(f); }
  void OnClose(Client&, const Status& reason) override { closes.push_back(reason); }
  void OnLinkEvent(Client&, const LinkEvent& e) override { link_events.push_back(e); }

  std::vector<Message> OfType(MessageType type) const {
    std::vector<Message> out;
    for (const Message& m : messages) {
      if (m.type == type) out.push_back(m);
    }
    return out;
  }
  std::size_t Count(MessageType type) const { return OfType(type).size(); }
};

// Sends `request` to 127.0.0.1:port and reads until the server closes (5 s timeout).
inline std::string RawHttpBlocking(std::uint16_t port, const std::string& request) {
  int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) return "socket failed";
  timeval tv{5, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  ::setsockopt(fd, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(port);
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
    ::close(fd);
    return "connect failed";
  }
  std::size_t sent = 0;
  while (sent < request.size()) {
    ssize_t n = ::send(fd, request.data() + sent, request.size() - sent, MSG_NOSIGNAL);
    if (n <= 0) break;
    sent += static_cast<std::size_t>(n);
  }
  std::string response;
  char buffer[4096];
  for (;;) {
    ssize_t n = ::recv(fd, buffer, sizeof buffer, 0);
    if (n <= 0) break;
    response.append(buffer, static_cast<std::size_t>(n));
  }
  ::close(fd);
  return response;
}

// Runs the raw request on another thread while this one runs the server's loop.
inline std::string RawHttp(EventLoop& loop, std::uint16_t port, const std::string& request) {
  auto future = std::async(std::launch::async, [port, request] { return RawHttpBlocking(port, request); });
  loop.RunUntil([&] { return future.wait_for(0s) == std::future_status::ready; }, 10s);
  return future.get();
}

inline std::string StatusLine(const std::string& response) { return response.substr(0, response.find("\r\n")); }
inline std::string Body(const std::string& response) {
  std::size_t end = response.find("\r\n\r\n");
  return end == std::string::npos ? "" : response.substr(end + 4);
}

}  // namespace teachsim::net::testing
