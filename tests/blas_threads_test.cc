// Library users get OpenBLAS at one thread per call without doing anything
// (arbor_slam/core/blas_threads.h): constructing a smoother is enough.
#include <dlfcn.h>

#include <cstdlib>

#include <gtest/gtest.h>

#include "arbor_slam/bayestree/incremental_smoother.h"
#include "arbor_slam/core/blas_threads.h"
#include "arbor_slam/core/se2.h"

namespace arbor {
namespace {

TEST(BlasThreads, SmootherConstructionLeavesOpenBlasAtOneThread) {
  using GetThreads = int (*)();
  auto get = reinterpret_cast<GetThreads>(dlsym(RTLD_DEFAULT, "openblas_get_num_threads"));
  if (!get) GTEST_SKIP() << "the BLAS in this process is not OpenBLAS";
  if (std::getenv("OPENBLAS_NUM_THREADS")) GTEST_SKIP() << "OPENBLAS_NUM_THREADS is set";
  IncrementalSmoother<SE2> smoother;
  EXPECT_EQ(get(), 1);
  EXPECT_EQ(useOneBlasThread(), BlasThreads::kSetToOne);  // and later calls say what was done
}

}  // namespace
}  // namespace arbor
