#include "teachsim/net/client.h"

#include <boost/asio/steady_timer.hpp>

#include "loop_internal.h"
#include "ws_connection.h"

namespace teachsim::net {

using internal::asio::ip::tcp;
namespace asio = internal::asio;
namespace beast = internal::beast;
namespace http = internal::http;
namespace websocket = internal::websocket;
using internal::WsConnection;
using json::Json;

Status ClientOptions::Validate() const {
  TEACHSIM_RETURN_IF_ERROR(limits.Validate());
  if (host.empty()) return Status::InvalidInput("ClientOptions::host must not be empty");
  if (port == 0) return Status::InvalidInput("ClientOptions::port must be set");
  if (path.empty() || path.front() != '/') return Status::InvalidInput("ClientOptions::path must start with '/'");
  if (heartbeat_period_s < 0 || heartbeat_period_s > 10) {
    return Status::InvalidInput("ClientOptions::heartbeat_period_s = " + json::FormatNumber(heartbeat_period_s) +
                                " must be in [0, 10] (0: no timer)");
  }
  TEACHSIM_RETURN_IF_ERROR(WatchdogOptions{link_timeout_s}.Validate());
  if (heartbeat_period_s > 0 && heartbeat_period_s >= link_timeout_s) {
    return Status::InvalidInput("ClientOptions::heartbeat_period_s must be below link_timeout_s");
  }
  if (!(connect_timeout_s > 0)) return Status::InvalidInput("ClientOptions::connect_timeout_s must be > 0");
  if (name.empty()) return Status::InvalidInput("ClientOptions::name must not be empty");
  return Status::Ok();
}

Result<WebSocketUrl> ParseWebSocketUrl(std::string_view url) {
  const std::string quoted = "\"" + std::string(url) + "\"";
  std::string_view rest = url;
  if (rest.substr(0, 5) == "ws://") {
    rest.remove_prefix(5);
  } else if (rest.find("://") != std::string_view::npos) {
    return Status::InvalidInput(quoted + ": only ws:// URLs are supported");
  }
  WebSocketUrl out;
  std::size_t slash = rest.find('/');
  std::string_view authority = rest.substr(0, slash);
  if (slash != std::string_view::npos) out.path = std::string(rest.substr(slash));
  std::string_view port_text;
  if (!authority.empty() && authority.front() == '[') {
    std::size_t close = authority.find(']');
    if (close == std::string_view::npos || close + 1 >= authority.size() || authority[close + 1] != ':') {
      return Status::InvalidInput(quoted + ": expected [IPv6]:PORT");
    }
    out.host = std::string(authority.substr(1, close - 1));
    port_text = authority.substr(close + 2);
  } else {
    std::size_t colon = authority.rfind(':');
    if (colon == std::string_view::npos) return Status::InvalidInput(quoted + ": expected HOST:PORT");
    out.host = std::string(authority.substr(0, colon));
    port_text = authority.substr(colon + 1);
  }
  if (out.host.empty()) return Status::InvalidInput(quoted + ": the host is empty");
  if (port_text.empty() || port_text.size() > 5 ||
      port_text.find_first_not_of("0123456789") != std::string_view::npos) {
    return Status::InvalidInput(quoted + ": the port must be a number in 1..65535");
  }
  int port = std::stoi(std::string(port_text));
  if (port < 1 || port > 65535) return Status::InvalidInput(quoted + ": the port must be a number in 1..65535");
  out.port = static_cast<std::uint16_t>(port);
  return out;
}

struct Client::Core : std::enable_shared_from_this<Client::Core> {
  enum class State { kIdle, kConnecting, kOpen };

  Core(EventLoop& loop, const Clock& clock_in, ClientOptions options_in, ClientHandler& handler_in, Client& owner)
      : io(IoContext(loop)),
        clock(&clock_in),
        options(std::move(options_in)),
        handler(&handler_in),
        client(&owner),
        resolver(io),
        timer(io),
        peer(clock_in, PeerOptions{options.limits, options.link_timeout_s}) {}

  asio::io_context& io;
  const Clock* clock;
  ClientOptions options;
  ClientHandler* handler;
  Client* client;  // null once the Client is gone
  tcp::resolver resolver;
  asio::steady_timer timer;
  Peer peer;
  State state = State::kIdle;
  std::uint64_t attempt = 0;  // stale completions of an earlier attempt are ignored
  std::shared_ptr<WsConnection> conn;
  std::optional<SessionId> session;
  bool heartbeats_paused = false;
  bool ticking = false;

  bool Live() const { return client != nullptr; }
  void Connect();
  void Opened();
  void Ended(std::uint64_t which, const Status& reason);
  void OnFrame(bool binary, std::string_view data);
  void Dispatch(Incoming in);
  void ScheduleTick();
  void Tick();
  void Drop();
};

void Client::Core::Connect() {
  if (state != State::kIdle) return;
  state = State::kConnecting;
  std::uint64_t which = ++attempt;
  Status valid = options.Validate();
  if (!valid.ok()) {
    asio::post(io, [weak = weak_from_this(), which, valid] {
      if (auto self = weak.lock()) self->Ended(which, valid);
    });
    return;
  }
  internal::ConnectionLimits limits{options.limits.max_json_bytes, options.limits.max_binary_bytes, 64u << 20};
  conn = std::make_shared<WsConnection>(io, limits);
  auto weak = weak_from_this();
  std::string where = options.host + ":" + std::to_string(options.port);
  resolver.async_resolve(
      options.host, std::to_string(options.port),
      [weak, which, where, c = conn](beast::error_code ec, tcp::resolver::results_type results) {
        auto self = weak.lock();
        if (!self || self->attempt != which) return;
        if (ec) return self->Ended(which, Status::IoError(where + ": cannot resolve: " + ec.message()));
        auto& stream = beast::get_lowest_layer(c->ws());
        stream.expires_after(FromSeconds(self->options.connect_timeout_s));
        stream.async_connect(results, [weak, which, where, c](beast::error_code ec2, const tcp::endpoint&) {
          auto self2 = weak.lock();
          if (!self2 || self2->attempt != which) return;
          if (ec2) return self2->Ended(which, Status::IoError(where + ": cannot connect: " + internal::DescribeError(ec2)));
          beast::get_lowest_layer(c->ws()).expires_never();
          beast::error_code ignored;
          beast::get_lowest_layer(c->ws()).socket().set_option(tcp::no_delay(true), ignored);
          websocket::stream_base::timeout timeout{};
          timeout.handshake_timeout = FromSeconds(self2->options.connect_timeout_s);
          timeout.idle_timeout = websocket::stream_base::none();
          timeout.keep_alive_pings = false;
          c->ws().set_option(timeout);
          std::string token = self2->options.token.secret();
          c->ws().set_option(websocket::stream_base::decorator([token](websocket::request_type& req) {
            req.set(http::field::user_agent, "teachsim");
            if (!token.empty()) req.set(http::field::authorization, "Bearer " + token);
          }));
          auto response = std::make_shared<websocket::response_type>();
          c->ws().async_handshake(*response, where, self2->options.path,
                                  [weak, which, where, c, response](beast::error_code ec3) {
                                    auto self3 = weak.lock();
                                    if (!self3 || self3->attempt != which) return;
                                    if (ec3) {
                                      std::string why = internal::DescribeError(ec3);
                                      if (ec3 == websocket::error::upgrade_declined) {
                                        why = "HTTP " + std::to_string(response->result_int()) + " " +
                                              std::string(response->reason());
                                      }
                                      return self3->Ended(which, Status::Failed(where + ": " + why));
                                    }
                                    self3->Opened();
                                  });
        });
      });
}

void Client::Core::Opened() {
  state = State::kOpen;
  session.reset();
  peer.ResetSequences();
  std::uint64_t which = attempt;
  auto weak = weak_from_this();
  conn->Start({
      [weak, which](bool binary, std::string_view data) {
        auto self = weak.lock();
        if (self && self->attempt == which) self->OnFrame(binary, data);
      },
      [weak, which](bool binary, std::size_t bytes) {
        auto self = weak.lock();
        if (self && self->attempt == which) self->Dispatch(self->peer.OnOversize(binary, bytes));
      },
      [weak, which](const std::string& reason) {
        if (auto self = weak.lock()) self->Ended(which, Status::IoError(reason));
      },
  });
  std::optional<LinkEvent> event = peer.OnConnected();
  if (options.send_hello) {
    Result<OutFrame> hello = peer.Encode(MessageType::kHello, {{"client", options.name}, {"protocol", kProtocolVersion}});
    if (hello.ok()) conn->Write(std::move(hello->data), false);
  }
  ScheduleTick();
  if (Live()) handler->OnOpen(*client);
  if (event && Live() && attempt == which) handler->OnLinkEvent(*client, *event);
}

void Client::Core::Ended(std::uint64_t which, const Status& reason) {
  if (attempt != which || state == State::kIdle) return;
  bool was_open = state == State::kOpen;
  state = State::kIdle;
  if (conn) {
    conn->Detach();
    conn->Abort();
    conn.reset();
  }
  session.reset();
  std::optional<LinkEvent> event = was_open ? peer.OnDisconnected() : std::nullopt;
  if (event && Live()) handler->OnLinkEvent(*client, *event);
  if (Live()) handler->OnClose(*client, reason);
}

void Client::Core::OnFrame(bool binary, std::string_view data) {
  Dispatch(binary ? peer.OnBinary(std::span(reinterpret_cast<const std::uint8_t*>(data.data()), data.size()))
                  : peer.OnText(data));
}

void Client::Core::Dispatch(Incoming in) {
  std::uint64_t which = attempt;
  for (OutFrame& reply : in.replies) {
    if (conn) conn->Write(std::move(reply.data), reply.binary);
  }
  if (in.link_event && Live()) handler->OnLinkEvent(*client, *in.link_event);
  if (!Live() || attempt != which || state != State::kOpen) return;
  if (in.message) {
    if (in.message->type == MessageType::kHeartbeat) return;
    if (in.message->type == MessageType::kWelcome) session = in.message->body.at("session").get<SessionId>();
    handler->OnMessage(*client, *in.message);
  } else if (in.frame) {
    handler->OnFrame(*client, *in.frame);
  }
}

void Client::Core::ScheduleTick() {
  if (options.heartbeat_period_s <= 0 || ticking) return;
  ticking = true;
  timer.expires_after(FromSeconds(options.heartbeat_period_s));
  timer.async_wait([weak = weak_from_this()](beast::error_code ec) {
    auto self = weak.lock();
    if (!self) return;
    self->ticking = false;
    if (ec || !self->Live()) return;
    self->Tick();
    // Keep ticking while connected; after a loss the watchdog has nothing more to say.
    if (self->state == State::kOpen) self->ScheduleTick();
  });
}

void Client::Core::Tick() {
  if (state != State::kOpen) return;
  if (!heartbeats_paused) {
    OutFrame heartbeat = peer.Heartbeat();
    conn->Write(std::move(heartbeat.data), false);
  }
  std::optional<LinkEvent> event = peer.Check();
  if (event && Live()) handler->OnLinkEvent(*client, *event);
}

void Client::Core::Drop() {
  ++attempt;  // every pending completion is now stale
  beast::error_code ignored;
  resolver.cancel();
  timer.cancel();
  ticking = false;
  if (conn) {
    conn->Detach();
    conn->Abort();
    conn.reset();
  }
  state = State::kIdle;
  session.reset();
}

Client::Client(EventLoop& loop, const Clock& clock, ClientOptions options, ClientHandler& handler)
    : core_(std::make_shared<Core>(loop, clock, std::move(options), handler, *this)) {}

Client::~Client() {
  core_->client = nullptr;
  core_->Drop();
}

void Client::Connect() { core_->Connect(); }

void Client::Reconnect() {
  if (core_->state != Core::State::kIdle) {
    bool was_open = core_->state == Core::State::kOpen;
    core_->Drop();
    std::optional<LinkEvent> event = was_open ? core_->peer.OnDisconnected() : std::nullopt;
    if (event) core_->handler->OnLinkEvent(*this, *event);
    core_->handler->OnClose(*this, Status::Failed("reconnecting"));
  }
  core_->Connect();
}

void Client::Close() {
  if (core_->state == Core::State::kOpen) {
    core_->conn->Close(websocket::close_reason(websocket::close_code::normal, "client closing"));
  } else if (core_->state == Core::State::kConnecting) {
    core_->Ended(core_->attempt, Status::Failed("closed while connecting"));
  }
}

void Client::Abort() {
  if (core_->state == Core::State::kIdle) return;
  core_->conn->Abort();  // the read loop reports the end
}

bool Client::connected() const { return core_->state == Core::State::kOpen; }
std::optional<SessionId> Client::session() const { return core_->session; }

Status Client::Send(MessageType type, Json fields) {
  if (core_->state != Core::State::kOpen) return Status::Failed("not connected");
  TEACHSIM_ASSIGN_OR_RETURN(OutFrame frame, core_->peer.Encode(type, std::move(fields)));
  if (!core_->conn->Write(std::move(frame.data), frame.binary)) return Status::Failed("send queue full or closing");
  return Status::Ok();
}

Status Client::SendFrame(const BinaryHeader& header, std::span<const std::uint8_t> pixels) {
  if (core_->state != Core::State::kOpen) return Status::Failed("not connected");
  TEACHSIM_ASSIGN_OR_RETURN(OutFrame frame, core_->peer.EncodeFrame(header, pixels));
  if (!core_->conn->Write(std::move(frame.data), frame.binary)) return Status::Failed("send queue full or closing");
  return Status::Ok();
}

Status Client::SendRaw(std::string data, bool binary) {
  if (core_->state != Core::State::kOpen) return Status::Failed("not connected");
  if (!core_->conn->Write(std::move(data), binary)) return Status::Failed("send queue full or closing");
  return Status::Ok();
}

void Client::Tick() { core_->Tick(); }
void Client::PauseHeartbeats(bool paused) { core_->heartbeats_paused = paused; }
LinkState Client::link() const { return core_->peer.watchdog().state(); }
PeerStats Client::stats() const { return core_->peer.stats(); }
const ClientOptions& Client::options() const { return core_->options; }

}  // namespace teachsim::net
