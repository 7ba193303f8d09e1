#include "teachsim/net/event_loop.h"

#include <algorithm>
#include <boost/asio/post.hpp>

#include "loop_internal.h"

namespace teachsim::net {

EventLoop::EventLoop() : impl_(std::make_unique<Impl>()) {}

EventLoop::~EventLoop() {
  impl_->guard.reset();
  impl_->io.stop();
}

std::size_t EventLoop::Poll() {
  if (impl_->io.stopped()) impl_->io.restart();
  return impl_->io.poll();
}

std::size_t EventLoop::RunFor(Duration duration) {
  if (impl_->io.stopped()) impl_->io.restart();
  return impl_->io.run_for(duration);
}

bool EventLoop::RunUntil(const std::function<bool()>& done, Duration timeout) {
  if (impl_->io.stopped()) impl_->io.restart();
  auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!done()) {
    auto now = std::chrono::steady_clock::now();
    if (now >= deadline) return done();
    // One handler at a time, waiting at most 5 ms for it: `done` may also turn true through
    // another thread, not only through a handler.
    impl_->io.run_one_for(std::min<std::chrono::steady_clock::duration>(deadline - now, std::chrono::milliseconds(5)));
    if (impl_->io.stopped()) impl_->io.restart();
  }
  return true;
}

void EventLoop::Run() {
  if (impl_->io.stopped()) impl_->io.restart();
  impl_->io.run();
}

void EventLoop::Stop() { impl_->io.stop(); }

void EventLoop::Post(std::function<void()> fn) { boost::asio::post(impl_->io, std::move(fn)); }

LoopThread::LoopThread(EventLoop& loop)
    : loop_(&loop), thread_([this] {
        // Short slices, so a Stop() that lands before a slice starts cannot be lost.
        while (!stop_.load()) loop_->RunFor(std::chrono::milliseconds(20));
      }) {}

LoopThread::~LoopThread() {
  stop_.store(true);
  loop_->Stop();
  thread_.join();
}

}  // namespace teachsim::net
