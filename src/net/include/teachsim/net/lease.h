// The controller lease (ABB calls it mastership): at most one session may command the work site
// (or drive the operator site's demonstration); every other session watches read-only. The lease
// is released explicitly or when its holder disconnects. Pure logic: the server calls it.
#pragma once

#include <cstdint>
#include <optional>

#include "teachsim/base/status.h"

namespace teachsim::net {

using SessionId = std::uint64_t;

class LeaseManager {
 public:
  // Grants the lease if it is free or already held by `session`; otherwise Failed naming the holder.
  [[nodiscard]] Status Request(SessionId session);
  // Releases the lease if `session` holds it; Failed if it does not.
  [[nodiscard]] Status Release(SessionId session);
  // A session went away: drops the lease if it held it. Returns whether it did.
  bool OnDisconnect(SessionId session);
  // Ok if `session` holds the lease, Failed ("read-only: the lease is held by session 3") otherwise.
  [[nodiscard]] Status CheckCommand(SessionId session) const;

  std::optional<SessionId> holder() const { return holder_; }
  bool Holds(SessionId session) const { return holder_ && *holder_ == session; }
  // Incremented on every change of holder, so observers can tell a re-grant from a stale state.
  std::uint64_t generation() const { return generation_; }

 private:
  std::optional<SessionId> holder_;
  std::uint64_t generation_ = 0;
};

}  // namespace teachsim::net
