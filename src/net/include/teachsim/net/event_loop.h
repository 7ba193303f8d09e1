// The event loop the server and client run on (a Boost.Asio io_context behind a small interface,
// so users of net never compile Asio). Servers, clients and their handlers run on the thread that
// runs the loop: either the caller's own (Poll / RunFor / RunUntil, as the tests do) or a
// LoopThread. Server and Client are not thread-safe; from another thread, Post() to the loop.
#pragma once

#include <atomic>
#include <functional>
#include <memory>
#include <thread>

#include "teachsim/net/clock.h"

namespace teachsim::net {

class EventLoop {
 public:
  EventLoop();
  ~EventLoop();
  EventLoop(const EventLoop&) = delete;
  EventLoop& operator=(const EventLoop&) = delete;

  // Runs the handlers that are ready, without waiting. Returns how many ran.
  std::size_t Poll();
  // Runs handlers for `duration` of wall-clock time (or until Stop()).
  std::size_t RunFor(Duration duration);
  // Runs handlers until `done()` holds or `timeout` passes; returns done(). Checks `done` after
  // every handler and at least every 5 ms, so it returns soon after the condition is met.
  bool RunUntil(const std::function<bool()>& done, Duration timeout);
  // Runs until Stop().
  void Run();
  // Makes Run / RunFor return soon; thread-safe. The next Run* call starts afresh.
  void Stop();
  // Queues `fn` to run on the loop's thread; thread-safe.
  void Post(std::function<void()> fn);

  struct Impl;
  Impl& impl() { return *impl_; }

 private:
  std::unique_ptr<Impl> impl_;
};

// Runs a loop on a thread of its own until destroyed (which stops the loop and joins). The loop
// must outlive every Server and Client on it; destroy those first (from the loop's thread, e.g.
// via Post, or after this LoopThread is gone).
class LoopThread {
 public:
  explicit LoopThread(EventLoop& loop);
  ~LoopThread();
  LoopThread(const LoopThread&) = delete;
  LoopThread& operator=(const LoopThread&) = delete;

 private:
  EventLoop* loop_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

}  // namespace teachsim::net
