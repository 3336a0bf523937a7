// Rate limit for log lines that a sender on the bus can trigger at will (refusals, transport
// state): at most one line per key per period; the lines held back meanwhile are counted and the
// next line of that key says how many. Memory: one entry per key (keys are a fixed set of
// reasons, never message contents).
#pragma once

#include <chrono>
#include <cstdint>
#include <map>
#include <mutex>
#include <string>

namespace arbor::serve {

class LogLimiter {
 public:
  using Clock = std::chrono::steady_clock;

  explicit LogLimiter(Clock::duration period = std::chrono::seconds(1)) : period_(period) {}

  /// Whether a line of `key` may be written at `now`. When it may and earlier ones were held
  /// back, `*suppressed` is their number (else 0).
  bool allow(const std::string& key, std::int64_t* suppressed,
             Clock::time_point now = Clock::now()) {
    std::lock_guard<std::mutex> lock(mutex_);
    Entry& e = entries_[key];
    if (e.written && now - e.last < period_) {
      ++e.suppressed;
      return false;
    }
    *suppressed = e.suppressed;
    e.suppressed = 0;
    e.last = now;
    e.written = true;
    return true;
  }

  /// `line` with " (N more like it in the last period not logged)" when lines were held back.
  static std::string withSuppressed(const std::string& line, std::int64_t suppressed) {
    if (suppressed == 0) return line;
    return line + " (" + std::to_string(suppressed) + " more like it not logged)";
  }

 private:
  struct Entry {
    Clock::time_point last;
    bool written = false;
    std::int64_t suppressed = 0;
  };
  Clock::duration period_;
  std::mutex mutex_;
  std::map<std::string, Entry> entries_;
};

}  // namespace arbor::serve
