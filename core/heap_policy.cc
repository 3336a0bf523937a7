#include "arbor_slam/core/heap_policy.h"

#include <cstdlib>
#include <cstring>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace arbor {
namespace {

bool userChoseMalloc() {
  const char* tunables = std::getenv("GLIBC_TUNABLES");
  if (tunables && std::strstr(tunables, "glibc.malloc.")) return true;
  return std::getenv("MALLOC_MMAP_THRESHOLD_") || std::getenv("MALLOC_TRIM_THRESHOLD_");
}

HeapPolicy setBoundedHeap(const HeapPolicyOptions& options) {
#if defined(__GLIBC__)
  if (userChoseMalloc()) return HeapPolicy::kUserChoice;
  mallopt(M_MMAP_THRESHOLD, static_cast<int>(options.mmap_threshold));
  mallopt(M_TRIM_THRESHOLD, static_cast<int>(options.trim_threshold));
  return HeapPolicy::kSet;
#else
  (void)options;
  return HeapPolicy::kNotGlibc;
#endif
}

}  // namespace

HeapPolicy useBoundedHeap(const HeapPolicyOptions& options) {
  static const HeapPolicy result = setBoundedHeap(options);  // thread-safe, once
  return result;
}

const char* toString(HeapPolicy policy) {
  switch (policy) {
    case HeapPolicy::kSet:
      return "set";
    case HeapPolicy::kUserChoice:
      return "user choice";
    case HeapPolicy::kNotGlibc:
      return "not glibc";
  }
  return "unknown";
}

}  // namespace arbor
