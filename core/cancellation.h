// A cancellation token for long solves: a handle to one shared atomic flag. Copies share the
// flag, so the caller keeps one copy, gives another to the solver through its options struct,
// and cancel() on either is seen by the solver at its next check (between iterations). No
// globals: each default-constructed token owns a fresh flag.
//
// For tests, cancelAfterChecks(k) makes the token report cancelled from its (k+1)-th check on:
// a deterministic "cancelled after iteration k" without a thread racing the solve, and
// checksPassed() counts the checks that let the solver go on, so a solve cut short by cancel()
// can be repeated exactly: cancelAfterChecks(checksPassed()) on a fresh token (the streaming
// service journals an exit refinement cut short that way).
#pragma once

#include <atomic>
#include <memory>

namespace arbor {

class CancellationToken {
 public:
  CancellationToken() : state_(std::make_shared<State>()) {}

  /// Asks every holder of this flag to stop at its next check.
  void cancel() const { state_->cancelled.store(true, std::memory_order_relaxed); }

  /// The solver's check: true once cancel() was called (or the countdown ran out).
  bool cancelled() const {
    if (state_->cancelled.load(std::memory_order_relaxed)) return true;
    if (state_->countdown.load(std::memory_order_relaxed) >= 0 &&
        state_->countdown.fetch_sub(1, std::memory_order_relaxed) <= 0) {
      cancel();
      return true;
    }
    state_->passed.fetch_add(1, std::memory_order_relaxed);
    return false;
  }

  /// The checks that returned false since construction or the last reset().
  int checksPassed() const { return state_->passed.load(std::memory_order_relaxed); }

  /// Cancels at the (checks + 1)-th call of cancelled() from now (checks ≥ 0; 0: the first).
  void cancelAfterChecks(int checks) const {
    state_->countdown.store(checks < 0 ? 0 : checks, std::memory_order_relaxed);
  }

  /// Clears the flag (and any countdown) for a new solve with the same token.
  void reset() const {
    state_->countdown.store(-1, std::memory_order_relaxed);
    state_->cancelled.store(false, std::memory_order_relaxed);
    state_->passed.store(0, std::memory_order_relaxed);
  }

  /// Whether the two handles are copies of one flag.
  bool sharesFlagWith(const CancellationToken& other) const { return state_ == other.state_; }

 private:
  struct State {
    std::atomic<bool> cancelled{false};
    std::atomic<int> countdown{-1};  ///< < 0: no countdown
    std::atomic<int> passed{0};      ///< checks that returned false
  };
  std::shared_ptr<State> state_;
};

}  // namespace arbor
