// The link watchdog: a link from which nothing (heartbeats included) has arrived for `timeout` is
// lost. The work site reacts to kLost by stopping the robot within a further 100 ms and latching
// the stop until the operator resumes (DESIGN.md, issue 8); kRestored reports traffic again, on
// the same connection or after a reconnect. Pure logic over an injected Clock.
#pragma once

#include <optional>
#include <string>

#include "teachsim/base/status.h"
#include "teachsim/net/clock.h"

namespace teachsim::net {

struct WatchdogOptions {
  double timeout_s = 0.25;  // silence after which the link counts as lost
  [[nodiscard]] Status Validate() const;
};

enum class LinkState { kIdle, kUp, kLost };
const char* LinkStateName(LinkState state);

struct LinkEvent {
  enum class Kind { kLost, kRestored } kind;
  double silent_s = 0;  // kLost: how long nothing had arrived (or 0 on a disconnect)
  std::string reason;   // "silent for 0.251 s", "disconnected", "traffic resumed", "reconnected"
};

class LinkWatchdog {
 public:
  LinkWatchdog(const Clock& clock, WatchdogOptions options);

  // Something arrived from the peer. Returns kRestored if the link was lost.
  std::optional<LinkEvent> OnReceived();
  // A (new) connection to the peer is up; counts as traffic. Returns kRestored if it was lost.
  std::optional<LinkEvent> OnConnected();
  // The connection closed: the link is lost at once (no need to wait for the silence).
  std::optional<LinkEvent> OnDisconnected();
  // Call periodically (every heartbeat period at least): returns kLost once when the silence
  // exceeds the timeout. A check that comes more than the timeout after the previous one (or after
  // the last arrival, for the first) says nothing: the checking thread itself was starved (a busy
  // machine, a long handler before it), and what arrived meanwhile may still wait in the socket
  // behind this check; the next check, one period later, decides. A real loss during the
  // starvation is then reported one check period later than otherwise.
  std::optional<LinkEvent> Check();

  LinkState state() const { return state_; }
  // Seconds since the last arrival (0 before the first connection).
  double SilentSeconds() const;
  const WatchdogOptions& options() const { return options_; }

 private:
  std::optional<LinkEvent> Restore(const char* reason);
  const Clock* clock_;
  WatchdogOptions options_;
  LinkState state_ = LinkState::kIdle;
  TimePoint last_received_{};
  TimePoint last_check_{};
};

}  // namespace teachsim::net
