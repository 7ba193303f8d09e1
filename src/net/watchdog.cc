#include "teachsim/net/watchdog.h"

#include "teachsim/base/json.h"

namespace teachsim::net {

Status WatchdogOptions::Validate() const {
  if (!(timeout_s > 0) || timeout_s > 60) {
    return Status::InvalidInput("WatchdogOptions::timeout_s = " + json::FormatNumber(timeout_s) +
                                " must be in (0, 60]");
  }
  return Status::Ok();
}

const char* LinkStateName(LinkState state) {
  switch (state) {
    case LinkState::kIdle: return "idle";
    case LinkState::kUp: return "up";
    case LinkState::kLost: return "lost";
  }
  return "?";
}

LinkWatchdog::LinkWatchdog(const Clock& clock, WatchdogOptions options)
    : clock_(&clock), options_(options) {
  TEACHSIM_CHECK_MSG(options_.Validate().ok(), "invalid WatchdogOptions");
}

std::optional<LinkEvent> LinkWatchdog::Restore(const char* reason) {
  bool was_lost = state_ == LinkState::kLost;
  state_ = LinkState::kUp;
  last_received_ = clock_->Now();
  last_check_ = last_received_;
  if (!was_lost) return std::nullopt;
  return LinkEvent{LinkEvent::Kind::kRestored, 0.0, reason};
}

std::optional<LinkEvent> LinkWatchdog::OnReceived() {
  if (state_ == LinkState::kIdle) return Restore("connected");
  // After a loss only a new connection (or traffic on the old one) brings the link back.
  return Restore("traffic resumed");
}

std::optional<LinkEvent> LinkWatchdog::OnConnected() { return Restore("reconnected"); }

std::optional<LinkEvent> LinkWatchdog::OnDisconnected() {
  if (state_ != LinkState::kUp) return std::nullopt;
  state_ = LinkState::kLost;
  return LinkEvent{LinkEvent::Kind::kLost, SilentSeconds(), "disconnected"};
}

std::optional<LinkEvent> LinkWatchdog::Check() {
  if (state_ != LinkState::kUp) return std::nullopt;
  const TimePoint now = clock_->Now();
  const double since_last_check = ToSeconds(now - last_check_);
  last_check_ = now;
  if (since_last_check > options_.timeout_s) return std::nullopt;  // starved: the next check decides
  double silent = SilentSeconds();
  if (silent <= options_.timeout_s) return std::nullopt;
  state_ = LinkState::kLost;
  return LinkEvent{LinkEvent::Kind::kLost, silent, "silent for " + json::FormatNumber(silent) + " s"};
}

double LinkWatchdog::SilentSeconds() const {
  if (state_ == LinkState::kIdle) return 0.0;
  return ToSeconds(clock_->Now() - last_received_);
}

}  // namespace teachsim::net
