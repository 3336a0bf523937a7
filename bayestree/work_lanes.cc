#include "arbor_slam/bayestree/work_lanes.h"

#include <chrono>
#include <stdexcept>
#include <string>

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#endif

namespace arbor::bayestree {
namespace {

// How long a thread out of work spins before it sleeps: the helper waiting for the next item,
// the caller waiting for the helper's last one.
constexpr long kHelperSpinNs = 50'000;
constexpr long kCallerSpinNs = 200'000;

inline void cpuRelax() {
#if defined(__x86_64__) || defined(__i386__)
  _mm_pause();
#endif
}

}  // namespace

WorkLanes::WorkLanes(int lanes) {
  if (lanes < 1)
    throw std::invalid_argument("WorkLanes: lanes must be at least 1, got " +
                                std::to_string(lanes));
  for (int lane = 1; lane < lanes; ++lane)
    helpers_.emplace_back([this, lane] { helperMain(lane); });
}

WorkLanes::~WorkLanes() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_all();
  for (std::thread& t : helpers_) t.join();
}

template <class Done>
void WorkLanes::await(std::unique_lock<std::mutex>& lock, const Done& done, long spin_ns) {
  lock.unlock();
  const auto start = std::chrono::steady_clock::now();
  for (int i = 1; !done(); ++i) {
    cpuRelax();
    if (i % 64 == 0 && std::chrono::duration_cast<std::chrono::nanoseconds>(
                           std::chrono::steady_clock::now() - start)
                               .count() > spin_ns)
      break;
  }
  lock.lock();
  wake_.wait(lock, done);
}

void WorkLanes::workOne(int lane, std::unique_lock<std::mutex>& lock) {
  int item = ready_.back();
  ready_.pop_back();
  pooled_.store(static_cast<int>(ready_.size()), std::memory_order_relaxed);
  busy_.fetch_add(1, std::memory_order_relaxed);
  lock.unlock();
  try {
    while (item >= 0) item = (*work_)(lane, item);
    lock.lock();
  } catch (...) {
    lock.lock();
    if (!error_) error_ = std::current_exception();
    ready_.clear();
    pooled_.store(0, std::memory_order_relaxed);
  }
  busy_.fetch_sub(1, std::memory_order_relaxed);
  if (ready_.empty() && busy_.load(std::memory_order_relaxed) == 0) wake_.notify_all();
}

void WorkLanes::run(const std::vector<int>& initial, const Work& work, bool share) {
  if (helpers_.empty() || !share) {  // one lane: a plain stack walk, no locking
    alone_.assign(initial.begin(), initial.end());
    alone_running_ = true;
    try {
      while (!alone_.empty()) {
        int item = alone_.back();
        alone_.pop_back();
        while (item >= 0) item = work(0, item);
      }
    } catch (...) {
      alone_running_ = false;  // later shared walks must pool their items again
      throw;
    }
    alone_running_ = false;
    return;
  }
  std::unique_lock<std::mutex> lock(mutex_);
  ready_.assign(initial.begin(), initial.end());
  pooled_.store(static_cast<int>(ready_.size()), std::memory_order_relaxed);
  work_ = &work;
  error_ = nullptr;
  if (ready_.size() > 1) wake_.notify_all();
  for (;;) {
    if (!ready_.empty()) {
      workOne(0, lock);
    } else if (busy_.load(std::memory_order_relaxed) == 0) {
      break;  // nothing pooled and nobody working who could pool more: done
    } else {
      idle_.fetch_add(1, std::memory_order_relaxed);
      await(
          lock,
          [this] {
            return pooled_.load(std::memory_order_acquire) > 0 ||
                   busy_.load(std::memory_order_acquire) == 0;
          },
          kCallerSpinNs);
      idle_.fetch_sub(1, std::memory_order_relaxed);
    }
  }
  // No helper is inside work() and none can enter it without an item: work_ may go.
  work_ = nullptr;
  if (error_) {
    std::exception_ptr e = error_;
    error_ = nullptr;
    std::rethrow_exception(e);
  }
}

void WorkLanes::push(int item) {
  if (alone_running_) {
    alone_.push_back(item);
    return;
  }
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (error_) return;
    ready_.push_back(item);
    pooled_.store(static_cast<int>(ready_.size()), std::memory_order_release);
  }
  wake_.notify_all();
}

void WorkLanes::helperMain(int lane) {
  std::unique_lock<std::mutex> lock(mutex_);
  for (;;) {
    if (stopping_) return;
    if (!ready_.empty()) {
      workOne(lane, lock);
      continue;
    }
    idle_.fetch_add(1, std::memory_order_relaxed);
    await(
        lock,
        [this] {
          return pooled_.load(std::memory_order_acquire) > 0 ||
                 stopping_.load(std::memory_order_acquire);
        },
        kHelperSpinNs);
    idle_.fetch_sub(1, std::memory_order_relaxed);
  }
}

}  // namespace arbor::bayestree
