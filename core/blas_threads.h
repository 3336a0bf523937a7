// One BLAS thread per call. The smoother's dense clique kernels (bayestree/dense_kernels.h) and
// CHOLMOD's supernodal factorisation call BLAS/LAPACK; a multi-threaded OpenBLAS (what
// scripts/install-deps.sh installs) would fan each large call out to every core, no faster on
// one core and fighting the smoother's own helper threads for them (measured: docs/design.md,
// "Dense clique kernels and the BLAS"). The smoother and the sparse Cholesky call this from
// their constructors, so a program that links the libraries gets it without doing anything.
#pragma once

namespace arbor {

/// What useOneBlasThread found and did.
enum class BlasThreads {
  kSetToOne,     ///< OpenBLAS was there and now runs one thread per call
  kUserChoice,   ///< OPENBLAS_NUM_THREADS was set: left as the user asked
  kNotOpenBlas,  ///< the BLAS in the process is not OpenBLAS: nothing to do
};

/// Once per process (later calls return the first call's result): when the process's BLAS is
/// OpenBLAS and OPENBLAS_NUM_THREADS is not set, openblas_set_num_threads(1) and stop OpenBLAS's
/// idle worker threads, which otherwise spin for about 0.1 s after start-up. A program that
/// wants more BLAS threads sets OPENBLAS_NUM_THREADS, or calls openblas_set_num_threads itself
/// after the first smoother or solver is constructed.
BlasThreads useOneBlasThread();

}  // namespace arbor
