// Seconds elapsed on the steady clock since a time point: the one definition the solvers, the
// smoother and the tools time their phases with.
#pragma once

#include <chrono>

namespace arbor {

inline double secondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace arbor
