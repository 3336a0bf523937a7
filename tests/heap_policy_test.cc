// core/heap_policy.h: with the fixed mmap threshold a freed large buffer does not move the
// threshold, so the next buffer of that size is mmapped again (and given back when freed) rather
// than carved out of the heap, where glibc's dynamic threshold would put it.
#include <malloc.h>

#include <cstdlib>
#include <cstring>

#include <gtest/gtest.h>

#include "arbor_slam/core/heap_policy.h"

namespace arbor {
namespace {

// One more mmapped block while `bytes` are held (mallinfo2's hblks), touching them so the
// allocation cannot be elided.
bool mmappedWhileHeld(size_t bytes) {
  const size_t before = mallinfo2().hblks;
  auto* p = static_cast<char*>(std::malloc(bytes));
  if (!p) return false;
  std::memset(p, 1, bytes);
  const char last = *static_cast<volatile char*>(p + bytes - 1);  // used: the allocation stays
  const bool mapped = mallinfo2().hblks > before;
  std::free(p);
  return mapped && last == 1;
}

TEST(HeapPolicy, LargeBuffersStayMappedAfterAFree) {
  const HeapPolicy policy = useBoundedHeap();
  if (policy != HeapPolicy::kSet)
    GTEST_SKIP() << "heap policy " << toString(policy) << " (GLIBC_TUNABLES or MALLOC_* set)";
  EXPECT_EQ(useBoundedHeap(), HeapPolicy::kSet);  // once per process
  const size_t big = size_t{3} << 20;             // above 1 MiB, below glibc's 32 MiB cap
  EXPECT_TRUE(mmappedWhileHeld(big));
  // glibc's dynamic rule would now raise the threshold past 3 MiB and serve this from the heap.
  EXPECT_TRUE(mmappedWhileHeld(big));
  EXPECT_FALSE(mmappedWhileHeld(size_t{64} << 10));  // small requests stay in the heap
}

}  // namespace
}  // namespace arbor
