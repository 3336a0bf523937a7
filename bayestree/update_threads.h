// The threads of one smoother update and what each uses while it works (SmootherOptions::threads):
// lane 0 is the caller's, lanes 1.. are WorkLanes' helpers. Shared by the units that walk the
// tree side by side — the linearisation (bayestree/linear_factors.h), the top elimination
// (bayestree/top_elimination.h) and the partial state update (bayestree/partial_solve.h) — and
// owned by the smoother, which passes it by reference. A copy gets threads of its own.
#pragma once

#include <cstddef>
#include <deque>
#include <vector>

#include "arbor_slam/bayestree/dense_kernels.h"
#include "arbor_slam/bayestree/work_lanes.h"

namespace arbor::bayestree {

/// What one thread uses while it eliminates or back-substitutes cliques (reused: no per-clique
/// malloc).
struct Lane {
  /// Per pose: its position in the clique being worked on, −1 otherwise (always restored to −1
  /// after use: no O(n) clearing). Lane 0's also serves the single-threaded steps.
  std::vector<int> slot;
  DoubleBuffer h;  ///< the clique's assembled Hessian
  std::vector<double> diag, x;
  std::vector<int> child_slots, changed_list;
  std::vector<int> solved_list;  ///< frontals of the cliques this thread solved (partial_solve.h)
  std::deque<int> pending;       ///< cliques this thread is to back-substitute
  int solved = 0, eliminated = 0, indeterminate = 0;  ///< cliques, in the current walk
};

struct UpdateThreads {
  explicit UpdateThreads(int n) : lanes(n), workers(n) {}
  UpdateThreads(const UpdateThreads& o)
      : lanes(o.lanes), ready(o.ready), workers(o.workers.lanes()) {}
  UpdateThreads& operator=(const UpdateThreads&) = delete;

  /// A new pose: a slot of its own in every lane.
  void addVariable() {
    for (Lane& l : lanes) l.slot.push_back(-1);
  }
  size_t scratchBytes() const {
    size_t bytes = 0;
    for (const Lane& l : lanes)
      bytes += (l.h.capacity() + l.diag.capacity() + l.x.capacity()) * sizeof(double);
    return bytes;
  }

  std::vector<Lane> lanes;
  std::vector<int> ready;  ///< the items a walk starts from
  WorkLanes workers;
};

}  // namespace arbor::bayestree
