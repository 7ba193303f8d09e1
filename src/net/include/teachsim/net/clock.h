// The clock the link code reads (STYLE.md: no hidden global state). Heartbeats, the watchdog and
// the lease stamp times with a Clock; tests drive a ManualClock so timing tests are deterministic.
#pragma once

#include <atomic>
#include <chrono>

namespace teachsim::net {

using Duration = std::chrono::nanoseconds;
using TimePoint = std::chrono::steady_clock::time_point;

inline double ToSeconds(Duration d) { return std::chrono::duration<double>(d).count(); }
inline Duration FromSeconds(double s) {
  return std::chrono::duration_cast<Duration>(std::chrono::duration<double>(s));
}

class Clock {
 public:
  virtual ~Clock() = default;
  virtual TimePoint Now() const = 0;
};

// Wall-clock monotonic time.
class SteadyClock final : public Clock {
 public:
  TimePoint Now() const override { return std::chrono::steady_clock::now(); }
};

// Time that moves only when told to. Starts at an arbitrary fixed point; thread-safe to read.
class ManualClock final : public Clock {
 public:
  TimePoint Now() const override { return TimePoint(Duration(now_ns_.load())); }
  void Advance(Duration d) { now_ns_ += d.count(); }
  void AdvanceSeconds(double s) { Advance(FromSeconds(s)); }

 private:
  std::atomic<long long> now_ns_{1'000'000'000'000LL};  // 1000 s: never mistaken for "unset"
};

}  // namespace teachsim::net
