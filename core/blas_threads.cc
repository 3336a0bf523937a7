#include "arbor_slam/core/blas_threads.h"

#include <dlfcn.h>

#include <cstdlib>

namespace arbor {
namespace {

BlasThreads setOneBlasThread() {
  if (std::getenv("OPENBLAS_NUM_THREADS")) return BlasThreads::kUserChoice;
  // Looked up at run time: the libraries link whatever BLAS Debian's alternatives give them.
  using SetThreads = void (*)(int);
  auto set = reinterpret_cast<SetThreads>(dlsym(RTLD_DEFAULT, "openblas_set_num_threads"));
  if (!set) return BlasThreads::kNotOpenBlas;
  set(1);
  // The worker threads OpenBLAS started when it was loaded spin (sched_yield) for a while
  // before they sleep, on the core the smoother's helper wants; with one thread per call they
  // are never used again, so stop them (OpenBLAS's own fork handler does the same; it would
  // restart them if more threads were asked for).
  using Shutdown = int (*)();
  if (auto shutdown = reinterpret_cast<Shutdown>(dlsym(RTLD_DEFAULT, "blas_thread_shutdown_")))
    shutdown();
  return BlasThreads::kSetToOne;
}

}  // namespace

BlasThreads useOneBlasThread() {
  static const BlasThreads result = setOneBlasThread();  // thread-safe, once
  return result;
}

}  // namespace arbor
