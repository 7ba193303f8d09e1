#include "teachsim/net/server.h"

#include <algorithm>
#include <boost/asio/steady_timer.hpp>
#include <boost/beast/http/file_body.hpp>
#include <map>

#include "loop_internal.h"
#include "teachsim/net/static_files.h"
#include "ws_connection.h"

namespace teachsim::net {

using internal::asio::ip::tcp;
namespace asio = internal::asio;
namespace beast = internal::beast;
namespace http = internal::http;
namespace websocket = internal::websocket;
using internal::WsConnection;
using json::Json;

Status ServerOptions::Validate() const {
  TEACHSIM_RETURN_IF_ERROR(limits.Validate());
  if (host.empty()) return Status::InvalidInput("ServerOptions::host must not be empty");
  if (heartbeat_period_s < 0 || heartbeat_period_s > 10) {
    return Status::InvalidInput("ServerOptions::heartbeat_period_s = " + json::FormatNumber(heartbeat_period_s) +
                                " must be in [0, 10] (0: no timer)");
  }
  TEACHSIM_RETURN_IF_ERROR(WatchdogOptions{link_timeout_s}.Validate());
  if (heartbeat_period_s > 0 && heartbeat_period_s >= link_timeout_s) {
    return Status::InvalidInput("ServerOptions::heartbeat_period_s = " + json::FormatNumber(heartbeat_period_s) +
                                " must be below link_timeout_s = " + json::FormatNumber(link_timeout_s));
  }
  if (!(close_after_silence_s >= link_timeout_s)) {
    return Status::InvalidInput("ServerOptions::close_after_silence_s = " + json::FormatNumber(close_after_silence_s) +
                                " must be >= link_timeout_s");
  }
  if (websocket_paths.empty()) return Status::InvalidInput("ServerOptions::websocket_paths must not be empty");
  for (const std::string& p : websocket_paths) {
    if (p.empty() || p.front() != '/') {
      return Status::InvalidInput("ServerOptions::websocket_paths: \"" + p + "\" must start with '/'");
    }
  }
  if (max_sessions < 1) return Status::InvalidInput("ServerOptions::max_sessions must be >= 1");
  if (max_request_header_bytes < 1024) {
    return Status::InvalidInput("ServerOptions::max_request_header_bytes must be >= 1024");
  }
  if (!(http_timeout_s > 0)) return Status::InvalidInput("ServerOptions::http_timeout_s must be > 0");
  if (max_send_queue_bytes < limits.max_binary_bytes) {
    return Status::InvalidInput("ServerOptions::max_send_queue_bytes must hold one binary message");
  }
  return Status::Ok();
}

namespace {

class HttpConnection;

std::string PathOf(std::string_view target) { return std::string(target.substr(0, target.find_first_of("?#"))); }

}  // namespace

struct Server::Core : std::enable_shared_from_this<Server::Core> {
  struct Session {
    SessionId id = 0;
    std::shared_ptr<WsConnection> conn;
    Peer peer;
    std::string remote, path, client_name;
    Session(const Clock& clock, PeerOptions options) : peer(clock, std::move(options)) {}
  };

  Core(EventLoop& loop, const Clock& clock_in, ServerOptions options_in, ServerHandler& handler_in, Server& owner)
      : io(IoContext(loop)),
        clock(&clock_in),
        options(std::move(options_in)),
        handler(&handler_in),
        server(&owner),
        acceptor(io),
        timer(io) {}

  asio::io_context& io;
  const Clock* clock;
  ServerOptions options;
  ServerHandler* handler;
  Server* server;  // null once the Server is gone: no more handler calls
  tcp::acceptor acceptor;
  asio::steady_timer timer;
  bool running = false;
  std::uint16_t port = 0;
  SessionId next_id = 1;
  std::map<SessionId, std::unique_ptr<Session>> sessions;
  std::vector<std::weak_ptr<HttpConnection>> http_connections;
  LeaseManager lease;

  bool Live() const { return running && server != nullptr; }
  Session* Find(SessionId id) {
    auto it = sessions.find(id);
    return it == sessions.end() ? nullptr : it->second.get();
  }

  void DoAccept();
  void ScheduleTick();
  void Tick();
  void Stop();
  void OnUpgrade(beast::tcp_stream stream, http::request<http::string_body> request, std::string remote);
  void OnSessionOpen(std::shared_ptr<WsConnection> conn, std::string path, std::string remote);
  void OnSessionFrame(SessionId id, bool binary, std::string_view data);
  void OnSessionOversize(SessionId id, bool binary, std::size_t bytes);
  void OnSessionClosed(SessionId id, const std::string& reason);
  void Dispatch(SessionId id, Incoming in);
  void HandleMessage(SessionId id, const Message& message);
  void ReportLink(SessionId id, const std::optional<LinkEvent>& event) {
    if (event && Live()) handler->OnLinkEvent(*server, id, *event);
  }
  void LeaseChanged();
  Status SendOut(Session& s, Result<OutFrame> frame) {
    if (!frame.ok()) return frame.status();
    if (!s.conn->Write(std::move(frame->data), frame->binary)) {
      return Status::Failed("session " + std::to_string(s.id) + ": send queue full or closing");
    }
    return Status::Ok();
  }
};

namespace {

// One HTTP connection until it upgrades (or closes): authentication, static files, upgrade.
class HttpConnection : public std::enable_shared_from_this<HttpConnection> {
 public:
  HttpConnection(tcp::socket socket, std::weak_ptr<Server::Core> core)
      : stream_(std::move(socket)), core_(std::move(core)) {
    beast::error_code ec;
    auto endpoint = stream_.socket().remote_endpoint(ec);
    if (!ec) remote_ = endpoint.address().to_string() + ":" + std::to_string(endpoint.port());
  }

  void Start() { DoRead(); }
  void Abort() {
    beast::error_code ignored;
    stream_.socket().shutdown(tcp::socket::shutdown_both, ignored);
    stream_.socket().close(ignored);
  }

 private:
  void DoRead() {
    auto core = core_.lock();
    if (!core || !core->Live()) return Abort();
    parser_.emplace();
    parser_->header_limit(static_cast<std::uint32_t>(core->options.max_request_header_bytes));
    parser_->body_limit(64 * 1024);
    stream_.expires_after(FromSeconds(core->options.http_timeout_s));
    http::async_read(stream_, buffer_, *parser_, beast::bind_front_handler(&HttpConnection::OnRead, shared_from_this()));
  }

  void OnRead(beast::error_code ec, std::size_t /*bytes*/) {
    auto core = core_.lock();
    if (!core || !core->Live()) return Abort();
    if (ec) {
      // The peer closed or went quiet: nothing to answer.
      if (ec == http::error::end_of_stream || ec == asio::error::eof || ec == beast::error::timeout ||
          ec == asio::error::operation_aborted) {
        return Abort();
      }
      // Not HTTP, or too large. A server with a token tells an unauthenticated peer nothing more.
      if (!core->options.token.empty()) return Respond(Unauthorized(11), false);
      if (ec == http::error::header_limit) return Respond(Simple(http::status::request_header_fields_too_large, 11), false);
      if (ec == http::error::body_limit) return Respond(Simple(http::status::payload_too_large, 11), false);
      return Respond(Simple(http::status::bad_request, 11), false);
    }
    http::request<http::string_body>& req = parser_->get();
    const ServerOptions& options = core->options;
    // Authentication comes first, before anything else is looked at or answered.
    if (!options.token.empty()) {
      auto it = req.find(http::field::authorization);
      std::string_view value = it == req.end() ? std::string_view() : std::string_view(it->value().data(), it->value().size());
      if (!Authorized(value, options.token)) return Respond(Unauthorized(req.version()), false);
    }
    std::string target(req.target().data(), req.target().size());
    std::string path = PathOf(target);
    if (websocket::is_upgrade(req)) {
      bool known = std::find(options.websocket_paths.begin(), options.websocket_paths.end(), path) !=
                   options.websocket_paths.end();
      if (!known) return Respond(Simple(http::status::not_found, req.version()), false);
      if (core->sessions.size() >= options.max_sessions) {
        return Respond(Simple(http::status::service_unavailable, req.version()), false);
      }
      stream_.expires_never();
      core->OnUpgrade(std::move(stream_), parser_->release(), remote_);
      return;
    }
    if (req.method() != http::verb::get && req.method() != http::verb::head) {
      auto res = Simple(http::status::method_not_allowed, req.version());
      res.set(http::field::allow, "GET, HEAD");
      return Respond(std::move(res), req.keep_alive());
    }
    if (options.static_root.empty()) return Respond(Simple(http::status::not_found, req.version()), req.keep_alive());
    Result<std::string> file = ResolveStaticPath(options.static_root, target);
    if (!file.ok()) {
      auto status = file.status().code() == StatusCode::kNotFound ? http::status::not_found : http::status::bad_request;
      return Respond(Simple(status, req.version()), req.keep_alive());
    }
    http::file_body::value_type body;
    body.open(file->c_str(), beast::file_mode::scan, ec);
    if (ec) return Respond(Simple(http::status::not_found, req.version()), req.keep_alive());
    std::uint64_t size = body.size();
    if (req.method() == http::verb::head) {
      http::response<http::empty_body> res{http::status::ok, req.version()};
      res.set(http::field::content_type, std::string(MimeType(*file)));
      res.content_length(size);
      return Respond(std::move(res), req.keep_alive());
    }
    http::response<http::file_body> res{std::piecewise_construct, std::make_tuple(std::move(body)),
                                        std::make_tuple(http::status::ok, req.version())};
    res.set(http::field::content_type, std::string(MimeType(*file)));
    res.set(http::field::cache_control, "no-cache");
    res.set("X-Content-Type-Options", "nosniff");
    res.content_length(size);
    Respond(std::move(res), req.keep_alive());
  }

  // 401 with an empty body: no hint of what the server is or serves.
  static http::response<http::string_body> Unauthorized(unsigned version) {
    http::response<http::string_body> res{http::status::unauthorized, version};
    res.set(http::field::www_authenticate, "Bearer");
    res.prepare_payload();
    return res;
  }

  static http::response<http::string_body> Simple(http::status status, unsigned version) {
    http::response<http::string_body> res{status, version};
    res.set(http::field::content_type, "text/plain; charset=utf-8");
    res.body() = std::string(http::obsolete_reason(status)) + "\n";
    res.prepare_payload();
    return res;
  }

  template <typename Body>
  void Respond(http::response<Body> response, bool keep_alive) {
    response.keep_alive(keep_alive);
    auto res = std::make_shared<http::response<Body>>(std::move(response));
    stream_.expires_after(std::chrono::seconds(10));
    http::async_write(stream_, *res, [self = shared_from_this(), res, keep_alive](beast::error_code ec, std::size_t) {
      if (ec || !keep_alive) {
        beast::error_code ignored;
        self->stream_.socket().shutdown(tcp::socket::shutdown_send, ignored);
        self->stream_.socket().close(ignored);
        return;
      }
      self->DoRead();
    });
  }

  beast::tcp_stream stream_;
  std::weak_ptr<Server::Core> core_;
  beast::flat_buffer buffer_;
  std::optional<http::request_parser<http::string_body>> parser_;
  std::string remote_;
};

}  // namespace

void Server::Core::DoAccept() {
  acceptor.async_accept([weak = weak_from_this()](beast::error_code ec, tcp::socket socket) {
    auto self = weak.lock();
    if (!self || !self->Live()) return;
    if (!ec) {
      beast::error_code ignored;
      socket.set_option(tcp::no_delay(true), ignored);  // small control frames must not wait (Nagle)
      auto conn = std::make_shared<HttpConnection>(std::move(socket), self);
      std::erase_if(self->http_connections, [](const auto& w) { return w.expired(); });
      self->http_connections.push_back(conn);
      conn->Start();
    }
    if (ec != asio::error::operation_aborted) self->DoAccept();
  });
}

void Server::Core::OnUpgrade(beast::tcp_stream stream, http::request<http::string_body> request, std::string remote) {
  internal::ConnectionLimits limits{options.limits.max_json_bytes, options.limits.max_binary_bytes,
                                    options.max_send_queue_bytes};
  auto conn = std::make_shared<WsConnection>(std::move(stream), limits);
  websocket::stream_base::timeout timeout{};
  timeout.handshake_timeout = FromSeconds(options.http_timeout_s);
  timeout.idle_timeout = websocket::stream_base::none();  // the link watchdog watches silence
  timeout.keep_alive_pings = false;
  conn->ws().set_option(timeout);
  conn->ws().set_option(websocket::stream_base::decorator(
      [](websocket::response_type& res) { res.set(http::field::server, "teachsim"); }));
  std::string path = PathOf(std::string_view(request.target().data(), request.target().size()));
  auto req = std::make_shared<http::request<http::string_body>>(std::move(request));
  conn->ws().async_accept(*req, [weak = weak_from_this(), conn, req, path, remote](beast::error_code ec) {
    auto self = weak.lock();
    if (ec || !self || !self->Live()) {
      conn->Abort();
      return;
    }
    self->OnSessionOpen(conn, path, remote);
  });
}

void Server::Core::OnSessionOpen(std::shared_ptr<WsConnection> conn, std::string path, std::string remote) {
  SessionId id = next_id++;
  auto session = std::make_unique<Session>(*clock, PeerOptions{options.limits, options.link_timeout_s});
  session->id = id;
  session->conn = conn;
  session->path = std::move(path);
  session->remote = std::move(remote);
  Session& s = *session;
  sessions.emplace(id, std::move(session));
  std::weak_ptr<Core> weak = weak_from_this();
  conn->Start({
      [weak, id](bool binary, std::string_view data) {
        if (auto self = weak.lock()) self->OnSessionFrame(id, binary, data);
      },
      [weak, id](bool binary, std::size_t bytes) {
        if (auto self = weak.lock()) self->OnSessionOversize(id, binary, bytes);
      },
      [weak, id](const std::string& reason) {
        if (auto self = weak.lock()) self->OnSessionClosed(id, reason);
      },
  });
  std::optional<LinkEvent> event = s.peer.OnConnected();
  Json welcome = {{"session", id},
                  {"protocol", kProtocolVersion},
                  {"server", options.name},
                  {"lease_holder", lease.holder() ? Json(*lease.holder()) : Json(nullptr)},
                  {"heartbeat_period_s", options.heartbeat_period_s > 0 ? options.heartbeat_period_s : 0.05},
                  {"link_timeout_s", options.link_timeout_s}};
  Status sent = SendOut(s, s.peer.Encode(MessageType::kWelcome, std::move(welcome)));
  TEACHSIM_CHECK_MSG(sent.ok(), sent.message().c_str());
  if (Live()) handler->OnOpen(*server, id);
  ReportLink(id, event);
}

void Server::Core::OnSessionFrame(SessionId id, bool binary, std::string_view data) {
  Session* s = Find(id);
  if (s == nullptr || !Live()) return;
  Incoming in = binary ? s->peer.OnBinary(std::span(reinterpret_cast<const std::uint8_t*>(data.data()), data.size()))
                       : s->peer.OnText(data);
  Dispatch(id, std::move(in));
}

void Server::Core::OnSessionOversize(SessionId id, bool binary, std::size_t bytes) {
  Session* s = Find(id);
  if (s == nullptr || !Live()) return;
  Dispatch(id, s->peer.OnOversize(binary, bytes));
}

void Server::Core::Dispatch(SessionId id, Incoming in) {
  Session* s = Find(id);
  for (OutFrame& reply : in.replies) s->conn->Write(std::move(reply.data), reply.binary);
  ReportLink(id, in.link_event);
  if (!Live() || Find(id) == nullptr) return;  // the handler may have closed it
  if (in.message) {
    HandleMessage(id, *in.message);
  } else if (in.frame) {
    handler->OnFrame(*server, id, *in.frame);
  }
}

void Server::Core::HandleMessage(SessionId id, const Message& message) {
  Session* s = Find(id);
  auto refuse = [&](const std::string& code, const std::string& text) {
    Status sent = SendOut(*s, s->peer.Encode(MessageType::kError, {{"code", code}, {"message", text}, {"in_reply_to", message.seq}}));
    (void)sent;  // a full queue: the peer is too slow to hear it anyway
  };
  switch (message.type) {
    case MessageType::kHeartbeat:
      return;
    case MessageType::kHello: {
      if (message.body.at("protocol").get<int>() != kProtocolVersion) {
        refuse("protocol_mismatch", "hello.protocol: this server speaks protocol " + std::to_string(kProtocolVersion) +
                                        ", got " + std::to_string(message.body.at("protocol").get<int>()));
        s->conn->Close(websocket::close_reason(websocket::close_code::protocol_error, "protocol mismatch"));
        return;
      }
      s->client_name = message.body.at("client").get<std::string>();
      break;
    }
    case MessageType::kLeaseRequest:
    case MessageType::kLeaseRelease: {
      if (!options.lease) break;
      std::uint64_t before = lease.generation();
      if (message.type == MessageType::kLeaseRequest) {
        Status granted = lease.Request(id);
        Json fields = {{"granted", granted.ok()},
                       {"holder", lease.holder() ? Json(*lease.holder()) : Json(nullptr)}};
        if (!granted.ok()) fields["reason"] = granted.message();
        (void)SendOut(*s, s->peer.Encode(MessageType::kLeaseGrant, std::move(fields)));
      } else {
        Status released = lease.Release(id);
        if (!released.ok()) refuse("not_lease_holder", released.message());
      }
      if (lease.generation() != before) LeaseChanged();
      return;
    }
    default:
      break;
  }
  if (options.lease && Spec(message.type).needs_lease) {
    Status allowed = lease.CheckCommand(id);
    if (!allowed.ok()) {
      refuse("not_lease_holder", std::string(TypeName(message.type)) + ": " + allowed.message());
      return;
    }
  }
  handler->OnMessage(*server, id, message);
}

void Server::Core::LeaseChanged() {
  Json fields = {{"holder", lease.holder() ? Json(*lease.holder()) : Json(nullptr)}, {"generation", lease.generation()}};
  for (auto& [id, s] : sessions) (void)SendOut(*s, s->peer.Encode(MessageType::kLeaseState, fields));
  if (Live()) handler->OnLeaseChanged(*server, lease.holder());
}

void Server::Core::OnSessionClosed(SessionId id, const std::string& reason) {
  auto it = sessions.find(id);
  if (it == sessions.end()) return;
  std::unique_ptr<Session> s = std::move(it->second);
  sessions.erase(it);
  if (!Live()) return;
  std::optional<LinkEvent> event = s->peer.OnDisconnected();
  if (options.lease && lease.OnDisconnect(id)) LeaseChanged();
  ReportLink(id, event);
  if (Live()) handler->OnClose(*server, id, reason);
}

void Server::Core::ScheduleTick() {
  if (options.heartbeat_period_s <= 0 || !running) return;
  timer.expires_after(FromSeconds(options.heartbeat_period_s));
  timer.async_wait([weak = weak_from_this()](beast::error_code ec) {
    auto self = weak.lock();
    if (ec || !self || !self->Live()) return;
    self->Tick();
    self->ScheduleTick();
  });
}

void Server::Core::Tick() {
  std::vector<SessionId> ids;
  for (const auto& [id, s] : sessions) ids.push_back(id);
  for (SessionId id : ids) {
    Session* s = Find(id);
    if (s == nullptr || !Live()) continue;
    OutFrame heartbeat = s->peer.Heartbeat();
    s->conn->Write(std::move(heartbeat.data), false);
    double silent = s->peer.watchdog().SilentSeconds();
    ReportLink(id, s->peer.Check());
    s = Find(id);
    if (s != nullptr && silent > options.close_after_silence_s) {
      s->conn->Close(websocket::close_reason(websocket::close_code::going_away, "link silent"));
    }
  }
}

void Server::Core::Stop() {
  if (!running) return;
  running = false;
  beast::error_code ignored;
  acceptor.close(ignored);
  timer.cancel();
  for (auto& weak : http_connections) {
    if (auto conn = weak.lock()) conn->Abort();
  }
  http_connections.clear();
  for (auto& [id, s] : sessions) {
    s->conn->Detach();
    s->conn->Close(websocket::close_reason(websocket::close_code::going_away, "server stopping"));
  }
  sessions.clear();
  lease = LeaseManager();
}

Server::Server(EventLoop& loop, const Clock& clock, ServerOptions options, ServerHandler& handler)
    : core_(std::make_shared<Core>(loop, clock, std::move(options), handler, *this)) {}

Server::~Server() {
  Stop();
  core_->server = nullptr;
}

Status Server::Start() {
  TEACHSIM_RETURN_IF_ERROR(core_->options.Validate());
  if (core_->running) return Status::Internal("Server::Start called twice");
  const std::string where = core_->options.host + ":" + std::to_string(core_->options.port);
  beast::error_code ec;
  asio::ip::address address = asio::ip::make_address(core_->options.host, ec);
  if (ec) return Status::InvalidInput(where + ": not an IP address (" + ec.message() + ")");
  tcp::endpoint endpoint(address, core_->options.port);
  tcp::acceptor& acceptor = core_->acceptor;
  acceptor.open(endpoint.protocol(), ec);
  if (!ec) acceptor.set_option(asio::socket_base::reuse_address(true), ec);
  if (!ec) acceptor.bind(endpoint, ec);
  if (!ec) acceptor.listen(asio::socket_base::max_listen_connections, ec);
  if (ec) {
    beast::error_code ignored;
    acceptor.close(ignored);
    return Status::IoError(where + ": cannot listen: " + ec.message());
  }
  core_->port = acceptor.local_endpoint().port();
  core_->running = true;
  core_->DoAccept();
  core_->ScheduleTick();
  return Status::Ok();
}

void Server::Stop() { core_->Stop(); }

std::uint16_t Server::port() const { return core_->port; }

Status Server::Send(SessionId session, MessageType type, Json fields) {
  Core::Session* s = core_->Find(session);
  if (s == nullptr) return Status::NotFound("session " + std::to_string(session) + " is not open");
  return core_->SendOut(*s, s->peer.Encode(type, std::move(fields)));
}

Status Server::SendFrame(SessionId session, const BinaryHeader& header, std::span<const std::uint8_t> pixels) {
  Core::Session* s = core_->Find(session);
  if (s == nullptr) return Status::NotFound("session " + std::to_string(session) + " is not open");
  return core_->SendOut(*s, s->peer.EncodeFrame(header, pixels));
}

std::size_t Server::Broadcast(MessageType type, const Json& fields) {
  std::size_t sent = 0;
  for (auto& [id, s] : core_->sessions) sent += core_->SendOut(*s, s->peer.Encode(type, fields)).ok() ? 1 : 0;
  return sent;
}

std::size_t Server::BroadcastFrame(const BinaryHeader& header, std::span<const std::uint8_t> pixels) {
  std::size_t sent = 0;
  for (auto& [id, s] : core_->sessions) sent += core_->SendOut(*s, s->peer.EncodeFrame(header, pixels)).ok() ? 1 : 0;
  return sent;
}

void Server::Close(SessionId session, const std::string& reason) {
  Core::Session* s = core_->Find(session);
  if (s == nullptr) return;
  s->conn->Close(websocket::close_reason(websocket::close_code::normal, reason.substr(0, 120)));
}

void Server::Tick() {
  if (core_->Live()) core_->Tick();
}

std::vector<SessionId> Server::Sessions() const {
  std::vector<SessionId> ids;
  for (const auto& [id, s] : core_->sessions) ids.push_back(id);
  return ids;
}

std::optional<SessionInfo> Server::Info(SessionId session) const {
  Core::Session* s = core_->Find(session);
  if (s == nullptr) return std::nullopt;
  return SessionInfo{s->id, s->remote, s->path, s->client_name, s->peer.watchdog().state(), s->peer.stats()};
}

const LeaseManager& Server::lease() const { return core_->lease; }
const ServerOptions& Server::options() const { return core_->options; }

}  // namespace teachsim::net
