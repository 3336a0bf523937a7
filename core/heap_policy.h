// How the process's heap gives memory back. glibc's malloc serves a request of at least its mmap
// threshold by mmap and returns it to the system on free; smaller ones come from the heap, whose
// free chunks stay with the process. The threshold is dynamic by default: each free of an
// mmapped chunk raises it to that chunk's size (up to 32 MiB on 64 bits). The smoother frees and
// reallocates clique storage of 1–35 MiB whenever it re-eliminates a top or re-orders, so after
// the first such free those buffers come from the heap, and what they leave behind stays there:
// at 1,000,000 poses 1.57 GB of the heap was free chunks (docs/benchmarks.md, "The 1,000,000-pose
// world in the smoother"). A fixed threshold keeps every buffer of 1 MiB or more in its own
// mapping, returned when freed, and stops the dynamic rise.
//
// The price: every large buffer then comes from fresh pages, so where every update
// re-eliminates a large top the page faults cost (sphere_bignoise with false closures: 40% more
// time). Process-wide, so the libraries never call it on their own (a host process may have its
// own reasons); `arbor replay|serve --bounded-heap` call it, and a program that holds a very
// large graph can too.
#pragma once

#include <cstddef>

namespace arbor {

/// What useBoundedHeap found and did.
enum class HeapPolicy {
  kSet,         ///< mallopt set the thresholds below
  kUserChoice,  ///< GLIBC_TUNABLES or MALLOC_MMAP_THRESHOLD_ names a malloc setting: left alone
  kNotGlibc,    ///< not glibc's malloc: nothing to do
};

struct HeapPolicyOptions {
  /// M_MMAP_THRESHOLD: requests of this many bytes or more are mmapped (fixed: no dynamic rise).
  std::size_t mmap_threshold = std::size_t{1} << 20;
  /// M_TRIM_THRESHOLD: free memory at the heap's top beyond this is returned (setting the mmap
  /// threshold fixes this one too, at glibc's 128 KiB unless given; 64 MiB saves the system
  /// calls of trimming a busy heap's top after every large free).
  std::size_t trim_threshold = std::size_t{64} << 20;
};

/// Once per process (later calls return the first call's result, whatever their options).
HeapPolicy useBoundedHeap(const HeapPolicyOptions& options = {});

const char* toString(HeapPolicy policy);  ///< "set", "user choice", "not glibc"

}  // namespace arbor
