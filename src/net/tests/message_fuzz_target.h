// The body of the message fuzzer (fuzz/message_fuzzer.cc), shared with corpus_test.cc so the
// normal gcc build also runs every corpus file through it. Any input must give a message or an
// error (never a crash), and the outcomes must be self-consistent: a parsed message re-validates
// and round-trips; a parsed frame re-encodes to the same bytes; every error reply is itself a
// valid "error" message. A violation aborts (the fuzzer reports it; the gtest dies).
#pragma once

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <span>
#include <string_view>

#include "teachsim/net/clock.h"
#include "teachsim/net/messages.h"
#include "teachsim/net/peer.h"

namespace teachsim::net::fuzz {

inline void Require(bool condition, const char* what) {
  if (!condition) {
    std::fprintf(stderr, "message fuzz target: invariant violated: %s\n", what);
    std::abort();
  }
}

inline void CheckReply(const OutFrame& reply, const MessageLimits& limits) {
  Require(!reply.binary, "replies are text");
  Parsed p = ParseTextMessage(reply.data, limits);
  Require(p.ok(), "an error reply parses");
  Require(p.message->type == MessageType::kError, "replies are error messages");
}

inline void RunMessageInput(const std::uint8_t* data, std::size_t size) {
  MessageLimits limits;
  limits.max_json_bytes = 64 * 1024;  // small limits so that the size checks are reached too
  limits.max_binary_bytes = 256 * 1024;
  std::string_view text(reinterpret_cast<const char*>(data), size);
  std::span<const std::uint8_t> bytes(data, size);

  Parsed t = ParseTextMessage(text, limits);
  Require(t.message.has_value() != t.error.has_value(), "text: exactly one of message / error");
  Require(!t.frame.has_value(), "text: no frame");
  if (t.message) {
    Require(ValidateMessage(t.message->body).ok(), "a parsed message re-validates");
    Parsed again = ParseTextMessage(Serialize(t.message->body), limits);
    Require(again.ok() && again.message->body == t.message->body, "a parsed message round-trips");
  } else {
    Require(!t.error->code.empty() && !t.error->message.empty(), "an error has a code and a message");
    Require(ParseTextMessage(Serialize(MakeErrorMessage(1, *t.error)), limits).ok(), "the error reply is valid");
  }

  Parsed b = ParseBinaryMessage(bytes, limits);
  Require(b.frame.has_value() != b.error.has_value(), "binary: exactly one of frame / error");
  if (b.frame) {
    Result<std::string> encoded = EncodeBinaryFrame(b.frame->header, b.frame->pixels);
    Require(encoded.ok(), "a parsed frame re-encodes");
    // Every header field is carried (reserved bytes included), so the encoding is the input.
    Require(*encoded == text, "a parsed frame re-encodes to the same bytes");
  }

  // The same bytes through a peer, as text and as binary, several times (sequence tracking).
  ManualClock clock;
  PeerOptions options;
  options.limits = limits;
  Peer peer(clock, options);
  (void)peer.OnConnected();
  for (int i = 0; i < 2; ++i) {
    Incoming in = peer.OnText(text);
    for (const OutFrame& reply : in.replies) CheckReply(reply, limits);
    Incoming ib = peer.OnBinary(bytes);
    for (const OutFrame& reply : ib.replies) CheckReply(reply, limits);
  }
  Incoming over = peer.OnOversize(size % 2 == 0, size);
  for (const OutFrame& reply : over.replies) CheckReply(reply, limits);
  Require(peer.stats().received == 5, "every frame is counted");
}

}  // namespace teachsim::net::fuzz
