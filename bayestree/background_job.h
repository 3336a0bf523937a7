// One piece of work on a state of its own, run on a background thread (at nice +10, as the
// relinearisation job and the batch refinement: the update path comes first) or on the calling
// thread. The owner hands the state over at start() and takes it back, worked on, at take(); the
// work reads and writes nothing else. The asynchronous relinearisation's catch-up
// (incremental_smoother.cc: the swap's fold-ins run on a copy of the smoother's state) is one.
// The destructor waits for a running job; a copy of a handle with a job waits for it and copies
// the state.
#pragma once

#include <atomic>
#include <exception>
#include <functional>
#include <memory>
#include <thread>
#include <utility>

#include "arbor_slam/core/thread_priority.h"

namespace arbor::bayestree {

template <class State>
class BackgroundJob {
 public:
  BackgroundJob() = default;
  ~BackgroundJob() { join(); }
  BackgroundJob(const BackgroundJob& other) {
    if (!other.job_) return;
    other.join();
    job_ = std::make_unique<Job>();
    job_->state = std::make_unique<State>(*other.job_->state);
    job_->error = other.job_->error;
    job_->started_at = other.job_->started_at;
    job_->done.store(true);
  }
  BackgroundJob& operator=(const BackgroundJob& other) {
    if (this != &other) {
      BackgroundJob copy(other);
      *this = std::move(copy);
    }
    return *this;
  }
  BackgroundJob(BackgroundJob&&) noexcept = default;
  BackgroundJob& operator=(BackgroundJob&& other) noexcept {
    if (this != &other) {
      join();
      job_ = std::move(other.job_);
    }
    return *this;
  }

  /// Runs work(*state) (none may be pending); `synchronous`: before returning. `started_at`:
  /// the owner's mark (an update count), read back by startedAt().
  void start(std::unique_ptr<State> state, std::function<void(State&)> work, bool synchronous,
             int started_at) {
    join();
    job_ = std::make_unique<Job>();
    job_->state = std::move(state);
    job_->work = std::move(work);
    job_->started_at = started_at;
    Job* job = job_.get();
    if (synchronous) {
      job->run();
      return;
    }
    job->thread = std::thread([job] {
      lowerThisThreadsPriority();
      job->run();
    });
  }
  bool pending() const { return job_ != nullptr; }         ///< started, not yet taken
  bool done() const { return job_ && job_->done.load(); }  ///< pending and finished
  int startedAt() const { return job_->started_at; }
  /// Waits for the job and hands its state back (rethrows what the work threw).
  std::unique_ptr<State> take() {
    join();
    std::unique_ptr<Job> job = std::move(job_);
    if (job->error) std::rethrow_exception(job->error);
    return std::move(job->state);
  }
  /// Waits for a pending job and drops it.
  void abandon() {
    join();
    job_.reset();
  }

 private:
  struct Job {
    std::unique_ptr<State> state;
    std::function<void(State&)> work;
    std::exception_ptr error;
    int started_at = 0;
    std::atomic<bool> done{false};
    std::thread thread;
    void run() {
      try {
        work(*state);
      } catch (...) {
        error = std::current_exception();
      }
      done.store(true);
    }
  };
  void join() const {
    if (job_ && job_->thread.joinable()) job_->thread.join();
  }
  std::unique_ptr<Job> job_;
};

}  // namespace arbor::bayestree
