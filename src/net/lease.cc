#include "teachsim/net/lease.h"

#include <string>

namespace teachsim::net {

Status LeaseManager::Request(SessionId session) {
  if (holder_ && *holder_ != session) {
    return Status::Failed("the controller lease is held by session " + std::to_string(*holder_));
  }
  if (!holder_) {
    holder_ = session;
    ++generation_;
  }
  return Status::Ok();
}

Status LeaseManager::Release(SessionId session) {
  if (!Holds(session)) {
    return Status::Failed("session " + std::to_string(session) + " does not hold the controller lease");
  }
  holder_.reset();
  ++generation_;
  return Status::Ok();
}

bool LeaseManager::OnDisconnect(SessionId session) {
  if (!Holds(session)) return false;
  holder_.reset();
  ++generation_;
  return true;
}

Status LeaseManager::CheckCommand(SessionId session) const {
  if (Holds(session)) return Status::Ok();
  if (holder_) {
    return Status::Failed("read-only: the controller lease is held by session " + std::to_string(*holder_));
  }
  return Status::Failed("read-only: request the controller lease first (lease_request)");
}

}  // namespace teachsim::net
