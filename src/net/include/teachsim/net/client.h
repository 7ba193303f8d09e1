// The WebSocket client: connects to ws://host:port/path with "Authorization: Bearer <token>",
// sends and receives validated, numbered messages, sends heartbeats and watches the link, and
// reconnects when asked. Handler calls happen on the EventLoop's thread; the loop must outlive
// the Client.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>

#include "teachsim/base/json.h"
#include "teachsim/base/status.h"
#include "teachsim/net/auth.h"
#include "teachsim/net/clock.h"
#include "teachsim/net/event_loop.h"
#include "teachsim/net/lease.h"
#include "teachsim/net/messages.h"
#include "teachsim/net/peer.h"
#include "teachsim/net/watchdog.h"

namespace teachsim::net {

struct ClientOptions {
  std::string host = "127.0.0.1";
  std::uint16_t port = 0;
  std::string path = "/ws";
  Token token;                        // empty: no Authorization header
  std::string name = "teachsim";      // sent in "hello"
  bool send_hello = true;
  MessageLimits limits;
  double heartbeat_period_s = 0.05;   // 20 Hz; 0: no timer (call Tick() yourself)
  double link_timeout_s = 0.25;
  double connect_timeout_s = 5.0;
  [[nodiscard]] Status Validate() const;
};

// Where to connect: "ws://HOST:PORT/PATH", or "HOST:PORT" (DESIGN.md's --worksite HOST:PORT;
// path "/ws"). IPv6 hosts in brackets ("ws://[::1]:9000/ws"). InvalidInput names what is wrong.
struct WebSocketUrl {
  std::string host;
  std::uint16_t port = 0;
  std::string path = "/ws";
};
[[nodiscard]] Result<WebSocketUrl> ParseWebSocketUrl(std::string_view url);

class Client;

class ClientHandler {
 public:
  virtual ~ClientHandler() = default;
  virtual void OnOpen(Client& /*client*/) {}
  virtual void OnMessage(Client& /*client*/, const Message& /*message*/) {}
  virtual void OnFrame(Client& /*client*/, const BinaryFrame& /*frame*/) {}
  // The connection attempt failed or the connection closed. A refused token reads
  // "HTTP 401 Unauthorized". Called once per Connect().
  virtual void OnClose(Client& /*client*/, const Status& /*reason*/) {}
  // kLost when the server fell silent or the connection closed; kRestored on traffic again or
  // after a reconnect.
  virtual void OnLinkEvent(Client& /*client*/, const LinkEvent& /*event*/) {}
};

class Client {
 public:
  Client(EventLoop& loop, const Clock& clock, ClientOptions options, ClientHandler& handler);
  ~Client();
  Client(const Client&) = delete;
  Client& operator=(const Client&) = delete;

  // Starts connecting (resolve, TCP, WebSocket handshake with the token); OnOpen or OnClose follow.
  void Connect();
  // Drops the current connection, if any, and connects anew.
  void Reconnect();
  // Closes with a WebSocket close frame; OnClose follows.
  void Close();
  // Drops the TCP connection without a close frame, as a cut cable or a killed process would
  // (the server's watchdog, not a close frame, must notice). OnClose follows.
  void Abort();

  bool connected() const;
  // The session number the server assigned ("welcome"), once received.
  std::optional<SessionId> session() const;

  [[nodiscard]] Status Send(MessageType type, json::Json fields = json::Json::object());
  [[nodiscard]] Status SendFrame(const BinaryHeader& header, std::span<const std::uint8_t> pixels);
  // Sends a frame as is, unnumbered and unchecked: for robustness tests and fuzzing over the wire.
  [[nodiscard]] Status SendRaw(std::string data, bool binary);

  // Heartbeat and watchdog; runs on the timer, or call it yourself when the period is 0.
  void Tick();
  // Stops sending heartbeats (the watchdog keeps running): lets tests fall silent on a live socket.
  void PauseHeartbeats(bool paused);

  LinkState link() const;
  PeerStats stats() const;
  const ClientOptions& options() const;

  struct Core;

 private:
  std::shared_ptr<Core> core_;
};

}  // namespace teachsim::net
