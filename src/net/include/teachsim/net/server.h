// The HTTP + WebSocket server (Boost.Beast underneath). It
//  * listens on 127.0.0.1 unless told otherwise, on a given or an ephemeral port;
//  * with a token, answers every request that lacks "Authorization: Bearer <token>" with 401 and
//    closes: no upgrade, no file, no hint (constant-time compare, the token is never logged);
//  * upgrades WebSocket requests on the configured paths, one session each, several at once;
//  * serves static files from a folder (GET/HEAD; MIME types; 404; no path traversal);
//  * validates every incoming message (net::Peer), answers refused ones with "error" and keeps the
//    session open; numbers outgoing messages per session; sends heartbeats and runs a link
//    watchdog per session; handles the controller lease (lease_request / lease_release /
//    lease_state, and refuses lease-only messages from other sessions).
// Every handler call happens on the EventLoop's thread. The EventLoop must outlive the Server.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

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

struct ServerOptions {
  std::string host = "127.0.0.1";  // the loopback interface unless told otherwise
  std::uint16_t port = 0;          // 0: an ephemeral port (see Server::port())
  std::string name = "teachsim";   // sent in "welcome"
  std::string static_root;         // folder of static files; empty: none (404)
  std::vector<std::string> websocket_paths = {"/ws"};
  Token token;                     // empty: no authentication (the browser-facing server)
  MessageLimits limits;
  double heartbeat_period_s = 0.05;    // 20 Hz; 0: no timer (call Tick() yourself)
  double link_timeout_s = 0.25;        // silence that counts as a lost link
  double close_after_silence_s = 5.0;  // a session this silent is closed
  bool lease = true;                   // handle the controller lease (see lease.h)
  std::size_t max_sessions = 32;
  std::size_t max_send_queue_bytes = 64u << 20;  // per session; beyond it Send() fails
  std::size_t max_request_header_bytes = 8192;
  double http_timeout_s = 10.0;  // reading a request / the WebSocket handshake
  [[nodiscard]] Status Validate() const;
};

class Server;

// What the services implement. Heartbeats and lease messages are handled by the server and not
// passed on; everything else that passes validation is.
class ServerHandler {
 public:
  virtual ~ServerHandler() = default;
  virtual void OnOpen(Server& /*server*/, SessionId /*session*/) {}
  virtual void OnMessage(Server& /*server*/, SessionId /*session*/, const Message& /*message*/) {}
  virtual void OnFrame(Server& /*server*/, SessionId /*session*/, const BinaryFrame& /*frame*/) {}
  // The session is gone (closed by either side or the transport failed). Called once per session.
  virtual void OnClose(Server& /*server*/, SessionId /*session*/, const std::string& /*reason*/) {}
  // kLost when the session fell silent (or closed), kRestored when a silent one spoke again.
  virtual void OnLinkEvent(Server& /*server*/, SessionId /*session*/, const LinkEvent& /*event*/) {}
  virtual void OnLeaseChanged(Server& /*server*/, std::optional<SessionId> /*holder*/) {}
};

struct SessionInfo {
  SessionId id = 0;
  std::string remote;       // "127.0.0.1:54321"
  std::string path;         // the WebSocket path it connected to
  std::string client_name;  // from "hello", empty before it
  LinkState link = LinkState::kIdle;
  PeerStats stats;
};

class Server {
 public:
  Server(EventLoop& loop, const Clock& clock, ServerOptions options, ServerHandler& handler);
  ~Server();
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  // Binds and listens. Errors name the address: "127.0.0.1:80: cannot listen: Permission denied".
  [[nodiscard]] Status Start();
  // Stops accepting, closes every session (OnClose is not called after Stop) and the timer.
  void Stop();
  std::uint16_t port() const;

  // Sends a JSON message (numbered, validated: InvalidInput names a bad field). NotFound if the
  // session is gone; Failed if its send queue is full.
  [[nodiscard]] Status Send(SessionId session, MessageType type, json::Json fields = json::Json::object());
  [[nodiscard]] Status SendFrame(SessionId session, const BinaryHeader& header, std::span<const std::uint8_t> pixels);
  // Sends to every open session; returns how many accepted it.
  std::size_t Broadcast(MessageType type, const json::Json& fields = json::Json::object());
  std::size_t BroadcastFrame(const BinaryHeader& header, std::span<const std::uint8_t> pixels);
  // Closes a session with a WebSocket close frame carrying `reason`.
  void Close(SessionId session, const std::string& reason);

  // Sends heartbeats and checks every session's watchdog. Runs on the timer every
  // heartbeat_period_s; call it yourself when the period is 0 (deterministic tests).
  void Tick();

  std::vector<SessionId> Sessions() const;
  std::optional<SessionInfo> Info(SessionId session) const;
  const LeaseManager& lease() const;
  const ServerOptions& options() const;

  struct Core;

 private:
  std::shared_ptr<Core> core_;
};

}  // namespace teachsim::net
