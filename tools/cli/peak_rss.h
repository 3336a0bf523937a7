// The process's peak resident set size (getrusage's ru_maxrss: Linux's VmHWM), for the memory
// columns of the replay rows and `arbor bench growth`.
#pragma once

#include <sys/resource.h>

namespace arbor::cli {

/// Peak RSS of this process so far, in KiB (0 when getrusage fails).
inline long peakRssKb() {
  rusage usage{};
  if (getrusage(RUSAGE_SELF, &usage) != 0) return 0;
  return usage.ru_maxrss;  // KiB on Linux
}

}  // namespace arbor::cli
