// Shared inputs of the microbenchmarks: the generated graphs (deterministic by seed) and the
// process's resident-memory figures from /proc/self/status.
#pragma once

#include <fstream>
#include <string>
#include <vector>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

#include "arbor_slam/tools/generator/graph_generator.h"

namespace arbor::micro {

/// An M3500-style Manhattan world of `poses` poses (generator defaults otherwise, seed 1).
inline sim::Simulation<SE2> manhattanGraph(int poses) {
  sim::ManhattanOptions o;
  o.poses = poses;
  return sim::manhattanWorld(o);
}

/// A Cube-style 3D grid random walk of `poses` poses (generator defaults otherwise, seed 1).
inline sim::Simulation<SE3> gridGraph(int poses) {
  sim::GridOptions o;
  o.poses = poses;
  return sim::gridWorld(o);
}

/// A field of /proc/self/status in MiB (e.g. "VmHWM", "VmRSS"); 0 if unavailable.
inline double procStatusMiB(const std::string& field) {
  std::ifstream status("/proc/self/status");
  for (std::string line; std::getline(status, line);) {
    if (line.rfind(field + ":", 0) == 0) return std::stod(line.substr(field.size() + 1)) / 1024.0;
  }
  return 0.0;
}

/// Bytes the allocator has handed out and not had back, in MiB (glibc's mallinfo2; 0 elsewhere).
/// Unlike RSS, this excludes freed memory the allocator keeps.
inline double heapInUseMiB() {
#if defined(__GLIBC__) && (__GLIBC__ > 2 || (__GLIBC__ == 2 && __GLIBC_MINOR__ >= 33))
  const struct mallinfo2 m = mallinfo2();
  return static_cast<double>(m.uordblks + m.hblkhd) / (1024.0 * 1024.0);
#else
  return 0.0;
#endif
}

/// Resets the peak RSS (VmHWM) to the current RSS (Linux ≥ 4.0: "5" to /proc/self/clear_refs),
/// so that a later VmHWM is the peak of what ran in between. False if the kernel refused.
inline bool resetPeakRss() {
  std::ofstream clear("/proc/self/clear_refs");
  clear << "5";
  clear.flush();
  return static_cast<bool>(clear);
}

/// Registers BM_UpdateAtSize/manhattan and BM_UpdateAtSize/sphere at these graph sizes (poses,
/// at most 4000) (smoother_bench.cc).
void registerUpdateAtSize(const std::vector<int>& sizes);

}  // namespace arbor::micro
