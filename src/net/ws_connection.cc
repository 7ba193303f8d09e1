#include "ws_connection.h"

#include <algorithm>

namespace teachsim::net::internal {

namespace {
constexpr std::size_t kReadChunk = 64 * 1024;
}

std::string DescribeError(const beast::error_code& ec) {
  if (ec == websocket::error::closed) return "closed by peer";
  if (ec == asio::error::eof || ec == http::error::end_of_stream) return "connection closed by peer";
  if (ec == asio::error::operation_aborted) return "aborted";
  if (ec == beast::error::timeout) return "timed out";
  return ec.message();
}

WsConnection::WsConnection(beast::tcp_stream stream, ConnectionLimits limits)
    : ws_(std::move(stream)), limits_(limits) {
  // Beast's own cap only ends absurd streams; ordinary oversized frames are drained in OnRead.
  ws_.read_message_max(std::max<std::size_t>(64u << 20, 4 * std::max(limits.max_text_bytes, limits.max_binary_bytes)));
}

WsConnection::WsConnection(asio::io_context& io, ConnectionLimits limits)
    : WsConnection(beast::tcp_stream(io), limits) {}

void WsConnection::Start(Callbacks callbacks) {
  callbacks_ = std::move(callbacks);
  DoRead();
}

void WsConnection::DoRead() {
  ws_.async_read_some(buffer_, kReadChunk, beast::bind_front_handler(&WsConnection::OnRead, shared_from_this()));
}

void WsConnection::OnRead(beast::error_code ec, std::size_t /*bytes*/) {
  if (ec) {
    if (ec == websocket::error::closed && ws_.reason().code != websocket::close_code::none) {
      std::string why = ws_.reason().reason.c_str();
      Finish("closed by peer (code " + std::to_string(ws_.reason().code) + (why.empty() ? "" : ", " + why) + ")");
    } else {
      Finish(DescribeError(ec));
    }
    return;
  }
  bool binary = ws_.got_binary();
  std::size_t limit = binary ? limits_.max_binary_bytes : limits_.max_text_bytes;
  if (discarding_) {
    discarded_bytes_ += buffer_.size();
    buffer_.consume(buffer_.size());
  } else if (buffer_.size() > limit) {
    discarding_ = true;
    discarded_bytes_ = buffer_.size();
    buffer_.consume(buffer_.size());
  }
  if (ws_.is_message_done()) {
    if (discarding_) {
      std::size_t bytes = discarded_bytes_;
      discarding_ = false;
      discarded_bytes_ = 0;
      // Copies: the callback may Detach() this connection while it runs.
      if (auto on_oversize = callbacks_.on_oversize) on_oversize(binary, bytes);
    } else {
      std::string_view data(static_cast<const char*>(buffer_.data().data()), buffer_.size());
      if (auto on_frame = callbacks_.on_frame) on_frame(binary, data);
      buffer_.consume(buffer_.size());
    }
  }
  if (!closed_) DoRead();
}

bool WsConnection::Write(std::string data, bool binary) {
  if (closed_ || closing_) return false;
  if (queued_bytes_ + data.size() > limits_.max_queue_bytes) return false;
  queued_bytes_ += data.size();
  queue_.emplace_back(std::move(data), binary);
  if (!writing_) DoWrite();
  return true;
}

void WsConnection::DoWrite() {
  writing_ = true;
  ws_.binary(queue_.front().second);
  ws_.async_write(asio::buffer(queue_.front().first),
                  beast::bind_front_handler(&WsConnection::OnWrite, shared_from_this()));
}

void WsConnection::OnWrite(beast::error_code ec, std::size_t /*bytes*/) {
  writing_ = false;
  queued_bytes_ -= queue_.front().first.size();
  queue_.pop_front();
  if (ec) {
    queue_.clear();
    queued_bytes_ = 0;
    Finish(DescribeError(ec));
    return;
  }
  if (!queue_.empty()) {
    DoWrite();
  } else if (closing_ && !close_sent_) {
    DoClose();
  }
}

void WsConnection::Close(websocket::close_reason reason) {
  if (closed_ || closing_) return;
  closing_ = true;
  close_reason_ = std::move(reason);
  if (!writing_) DoClose();
}

void WsConnection::DoClose() {
  close_sent_ = true;
  ws_.async_close(close_reason_, [self = shared_from_this()](beast::error_code ec) {
    // The read loop reports the end; if it is not running (or the close failed), end here.
    if (ec) {
      beast::error_code ignored;
      beast::get_lowest_layer(self->ws_).socket().close(ignored);
      self->Finish(DescribeError(ec));
    }
  });
}

void WsConnection::Abort() {
  beast::error_code ignored;
  beast::get_lowest_layer(ws_).socket().shutdown(tcp::socket::shutdown_both, ignored);
  beast::get_lowest_layer(ws_).socket().close(ignored);
}

void WsConnection::Finish(const std::string& reason) {
  if (closed_) return;
  closed_ = true;
  auto on_closed = std::move(callbacks_.on_closed);
  callbacks_ = {};
  if (on_closed) on_closed(reason);
}

}  // namespace teachsim::net::internal
