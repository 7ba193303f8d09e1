// Inside net only: one WebSocket connection over Beast, shared by the server's sessions and the
// client. Reads frames in chunks so that an oversized one is drained and discarded with bounded
// memory (and reported, the connection staying usable) instead of Beast failing the connection;
// queues writes (Beast allows one at a time); closes gracefully after the queue drains.
#pragma once

#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <deque>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <utility>

namespace teachsim::net::internal {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
using tcp = asio::ip::tcp;
using WsStream = websocket::stream<beast::tcp_stream>;

struct ConnectionLimits {
  std::size_t max_text_bytes = 1 << 20;
  std::size_t max_binary_bytes = 8 << 20;
  std::size_t max_queue_bytes = 64u << 20;
};

class WsConnection : public std::enable_shared_from_this<WsConnection> {
 public:
  struct Callbacks {
    std::function<void(bool binary, std::string_view data)> on_frame;  // a whole frame within limits
    std::function<void(bool binary, std::size_t bytes)> on_oversize;   // a frame drained unread
    std::function<void(const std::string& reason)> on_closed;          // exactly once
  };

  WsConnection(beast::tcp_stream stream, ConnectionLimits limits);
  explicit WsConnection(asio::io_context& io, ConnectionLimits limits);

  WsStream& ws() { return ws_; }

  // Starts the read loop.
  void Start(Callbacks callbacks);
  // Queues a frame. False if closing/closed or the queue would exceed its limit.
  bool Write(std::string data, bool binary);
  // Sends a close frame once the queue has drained.
  void Close(websocket::close_reason reason);
  // Closes the socket at once (no close frame).
  void Abort();
  // Forgets the callbacks: nothing is reported after this.
  void Detach() { callbacks_ = {}; }
  bool closed() const { return closed_; }

 private:
  void DoRead();
  void OnRead(beast::error_code ec, std::size_t bytes);
  void DoWrite();
  void OnWrite(beast::error_code ec, std::size_t bytes);
  void DoClose();
  void Finish(const std::string& reason);

  WsStream ws_;
  ConnectionLimits limits_;
  beast::flat_buffer buffer_;
  bool discarding_ = false;
  std::size_t discarded_bytes_ = 0;
  std::deque<std::pair<std::string, bool>> queue_;
  std::size_t queued_bytes_ = 0;
  bool writing_ = false;
  bool closing_ = false;
  bool close_sent_ = false;
  bool closed_ = false;
  websocket::close_reason close_reason_;
  Callbacks callbacks_;
};

// Readable error text: "closed by peer (normal)", "connection reset", ...
std::string DescribeError(const beast::error_code& ec);

}  // namespace teachsim::net::internal
