// Inside net only: the io_context behind EventLoop.
#pragma once

#include <boost/asio/executor_work_guard.hpp>
#include <boost/asio/io_context.hpp>
#include <optional>

#include "teachsim/net/event_loop.h"

namespace teachsim::net {

struct EventLoop::Impl {
  boost::asio::io_context io{1};
  // Keeps Run()/RunFor() from returning merely because no operation is pending.
  std::optional<boost::asio::executor_work_guard<boost::asio::io_context::executor_type>> guard{
      boost::asio::make_work_guard(io)};
};

inline boost::asio::io_context& IoContext(EventLoop& loop) { return loop.impl().io; }

}  // namespace teachsim::net
