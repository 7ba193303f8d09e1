// One end of a connection, without the socket: numbers outgoing messages, validates incoming
// ones (answering each refused one with an "error" message), tracks the peer's sequence, keeps the
// link watchdog fed and measures round-trip time from heartbeat echoes. The server keeps one Peer
// per session and the client one per connection; tests drive it directly with a ManualClock.
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "teachsim/base/json.h"
#include "teachsim/base/status.h"
#include "teachsim/net/clock.h"
#include "teachsim/net/messages.h"
#include "teachsim/net/watchdog.h"

namespace teachsim::net {

struct PeerOptions {
  MessageLimits limits;
  double link_timeout_s = 0.25;
  [[nodiscard]] Status Validate() const;
};

// A frame to put on the wire.
struct OutFrame {
  std::string data;
  bool binary = false;
};

// What one incoming frame produced.
struct Incoming {
  std::optional<Message> message;     // a valid JSON message (heartbeats included)
  std::optional<BinaryFrame> frame;   // a valid binary frame
  std::optional<MessageError> error;  // why the frame was refused (already answered in `replies`)
  std::vector<OutFrame> replies;      // error messages to send back
  std::optional<LinkEvent> link_event;
};

struct PeerStats {
  std::uint64_t received = 0;         // frames received, valid or not
  std::uint64_t refused = 0;          // frames answered with an error
  std::uint64_t sent = 0;             // frames numbered by this peer
  std::uint64_t seq_gaps = 0;
  std::uint64_t seq_duplicates = 0;
  std::optional<double> rtt_s;        // last round trip measured from a heartbeat echo
};

class Peer {
 public:
  Peer(const Clock& clock, PeerOptions options);

  // Incoming frames. `OnOversize` reports a frame the transport discarded unread because it
  // exceeded the limit; it is answered like any other refused frame.
  Incoming OnText(std::string_view text);
  Incoming OnBinary(std::span<const std::uint8_t> bytes);
  Incoming OnOversize(bool binary, std::size_t bytes);

  // Outgoing: numbers and validates a JSON message; InvalidInput names a bad field (nothing is
  // numbered then, so the peer sees no gap).
  [[nodiscard]] Result<OutFrame> Encode(MessageType type, json::Json fields = json::Json::object());
  [[nodiscard]] Result<OutFrame> EncodeFrame(BinaryHeader header, std::span<const std::uint8_t> pixels);
  // The next heartbeat, echoing the last heartbeat received (for the peer's round-trip time).
  OutFrame Heartbeat();

  // Connection events and the periodic check, for the watchdog.
  std::optional<LinkEvent> OnConnected() { return watchdog_.OnConnected(); }
  std::optional<LinkEvent> OnDisconnected() { return watchdog_.OnDisconnected(); }
  std::optional<LinkEvent> Check() { return watchdog_.Check(); }
  const LinkWatchdog& watchdog() const { return watchdog_; }

  // A fresh connection: sequence numbers start again at 1 in both directions.
  void ResetSequences();

  const PeerStats& stats() const { return stats_; }
  const PeerOptions& options() const { return options_; }

 private:
  Incoming Refuse(Incoming in, MessageError error);
  // Observes the peer's seq; false (and `in` refused) for a duplicate, a gap is reported in replies.
  bool TrackSequence(std::optional<std::uint64_t> seq, Incoming* in);
  void OnHeartbeat(const Message& heartbeat);
  double NowSeconds() const;

  const Clock* clock_;
  PeerOptions options_;
  LinkWatchdog watchdog_;
  SequenceCounter out_seq_;
  SequenceTracker in_seq_;
  PeerStats stats_;
  TimePoint epoch_;
  std::optional<double> echo_t_s_;  // the peer's last heartbeat time, to echo back
  TimePoint echo_received_{};
};

}  // namespace teachsim::net
