// A scope in which OpenMP parallel regions run serially in the calling thread only.
// CHOLMOD 5 runs some loops of its supernodal factorisation with a hard-wired 4 OpenMP threads;
// on a small shared machine that oversubscription costs time (docs/design.md, "Batch solvers").
// (max-active-levels is a per-task ICV, so other threads are unaffected.)
#pragma once

#include <omp.h>

namespace arbor {

class SerialOpenMP {
 public:
  SerialOpenMP() : saved_(omp_get_max_active_levels()) { omp_set_max_active_levels(0); }
  ~SerialOpenMP() { omp_set_max_active_levels(saved_); }
  SerialOpenMP(const SerialOpenMP&) = delete;
  SerialOpenMP& operator=(const SerialOpenMP&) = delete;

 private:
  int saved_;
};

}  // namespace arbor
