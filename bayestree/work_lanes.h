// The calling thread and helper threads working together through one walk over a Bayes tree:
// the elimination (a clique is ready when its children are done) and the back-substitution (a
// clique is ready when its parent is done). Independent subtrees go to different cores; the
// result does not depend on who did what, because each clique reads only what its children (or
// its parent) wrote, and the walk waits for all of them.
#pragma once

#include <atomic>
#include <condition_variable>
#include <exception>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace arbor::bayestree {

/// A pool of ready items (clique ids) worked through by `lanes` threads: lane 0 is the thread
/// that calls run(), lanes 1.. are helper threads owned by this object. A thread that runs out
/// of work spins briefly before it sleeps (the items are microseconds long, a wake-up is
/// tens). One lane runs everything on the calling thread.
class WorkLanes {
 public:
  /// work(lane, item) processes `item` on `lane` (0 ≤ lane < lanes()) and returns an item it
  /// made ready to process next on the same lane, or −1; others it made ready go to push().
  using Work = std::function<int(int lane, int item)>;

  explicit WorkLanes(int lanes);
  ~WorkLanes();
  WorkLanes(const WorkLanes&) = delete;
  WorkLanes& operator=(const WorkLanes&) = delete;

  int lanes() const { return static_cast<int>(helpers_.size()) + 1; }

  /// Works through `initial` and everything made ready from it; returns when no item is left
  /// and no lane is working. The first exception thrown by `work` is rethrown here (the items
  /// still pooled are then dropped). `share` false: all on the calling thread (a walk too small
  /// to be worth a helper's wake-up). Not reentrant; one caller at a time.
  void run(const std::vector<int>& initial, const Work& work, bool share = true);

  /// From within work(): makes `item` ready for any lane.
  void push(int item);

  /// Whether another lane is out of work: a walk that keeps a stack of its own hands it an
  /// item with push() then (one relaxed load).
  bool hungry() const { return idle_.load(std::memory_order_relaxed) > 0; }

 private:
  // Takes the last pooled item, works through it and what it returns (lock held on entry and
  // exit, released while working).
  void workOne(int lane, std::unique_lock<std::mutex>& lock);
  // Spins until `done` (read without the lock) or a time limit, then sleeps until `done`.
  template <class Done>
  void await(std::unique_lock<std::mutex>& lock, const Done& done, long spin_ns);
  void helperMain(int lane);

  std::mutex mutex_;
  std::condition_variable wake_;  // an item pooled, a walk finished, shut-down
  // Changed only with the mutex held; atomic so that a spinning thread may read them without.
  std::vector<int> ready_;
  std::atomic<int> pooled_{0};  // ready_.size()
  std::atomic<int> busy_{0};    // lanes inside work()
  std::atomic<bool> stopping_{false};
  std::atomic<int> idle_{0};  // lanes waiting for an item
  const Work* work_ = nullptr;
  std::vector<int> alone_;      // the stack of a walk run on the calling thread alone
  bool alone_running_ = false;  // (helpers never see these)
  std::exception_ptr error_;
  std::vector<std::thread> helpers_;
};

}  // namespace arbor::bayestree
