#include "bayestree/dense_kernels.h"

#include <cmath>

#include <algorithm>
#include <cstddef>

// LAPACK / BLAS (Fortran calling convention; the trailing arguments are the lengths of the
// character arguments, as gfortran passes them).
extern "C" {
void dpotrf_(const char* uplo, const int* n, double* a, const int* lda, int* info, std::size_t);
void dtrsm_(const char* side, const char* uplo, const char* transa, const char* diag, const int* m,
            const int* n, const double* alpha, const double* a, const int* lda, double* b,
            const int* ldb, std::size_t, std::size_t, std::size_t, std::size_t);
void dsyrk_(const char* uplo, const char* trans, const int* n, const int* k, const double* alpha,
            const double* a, const int* lda, const double* beta, double* c, const int* ldc,
            std::size_t, std::size_t);
}

namespace arbor::bayestree {
namespace {

// A pivot below this fraction of its own diagonal entry, or of the clique's largest diagonal
// entry, marks a clique as indeterminate (nearly singular).
constexpr double kRelativePivot = 1e-10;
constexpr double kCliquePivot = 1e-14;

// Partial (left-looking) Cholesky of the lower triangle of the M×M matrix A (leading
// dimension lda): factors the first F columns (L and the rows below it, i.e. Sᵀ and d) and
// leaves the Schur complement in the trailing block. False when a pivot is not safely positive
// relative to its diagonal `dg` (the clique is then indeterminate).
bool partialCholeskySmall(double* A, int lda, int F, int M, const double* dg) {
  double max_diag = 0;
  for (int k = 0; k < F; ++k) max_diag = std::max(max_diag, dg[k]);
  const double floor = kCliquePivot * max_diag;
  for (int j = 0; j < M - 1; ++j) {  // the last column (g's diagonal) is not needed
    double* Aj = A + static_cast<size_t>(j) * lda;
    const int kmax = std::min(j, F);
    int k = 0;
    for (; k + 4 <= kmax; k += 4) {  // four columns at a time: one pass over column j
      const double* A0 = A + static_cast<size_t>(k) * lda;
      const double* A1 = A0 + lda;
      const double* A2 = A1 + lda;
      const double* A3 = A2 + lda;
      const double a0 = A0[j], a1 = A1[j], a2 = A2[j], a3 = A3[j];
      if (a0 == 0.0 && a1 == 0.0 && a2 == 0.0 && a3 == 0.0) continue;
      for (int i = j; i < M; ++i) Aj[i] -= (A0[i] * a0 + A1[i] * a1) + (A2[i] * a2 + A3[i] * a3);
    }
    for (; k < kmax; ++k) {
      const double* Ak = A + static_cast<size_t>(k) * lda;
      const double a = Ak[j];
      if (a == 0.0) continue;
      for (int i = j; i < M; ++i) Aj[i] -= Ak[i] * a;
    }
    if (j < F) {
      const double p = Aj[j];
      if (!std::isfinite(p) || !(p > kRelativePivot * dg[j]) || !(p > floor)) return false;
      const double r = std::sqrt(p);
      Aj[j] = r;
      const double inv = 1.0 / r;
      for (int i = j + 1; i < M; ++i) Aj[i] *= inv;
    }
  }
  return true;
}

// As partialCholeskySmall, with LAPACK's Cholesky and BLAS's triangular solve and rank update
// (for large cliques; OpenBLAS where installed): L = chol(A_ff) (dpotrf);
// [Sᵀ; dᵀ] = A_(s,g)f L⁻ᵀ (dtrsm); A_(s,g)(s,g) −= [Sᵀ; dᵀ][S d] (dsyrk, lower triangle).
bool partialCholeskyBlocked(double* A, int lda, int F, int M, const double* dg) {
  int info = 0;
  dpotrf_("L", &F, A, &lda, &info, 1);
  if (info != 0) return false;
  double max_diag = 0;
  for (int k = 0; k < F; ++k) max_diag = std::max(max_diag, dg[k]);
  const double floor = kCliquePivot * max_diag;
  for (int k = 0; k < F; ++k) {
    const double l = A[static_cast<size_t>(k) * lda + k];
    const double p = l * l;
    if (!std::isfinite(p) || !(p > kRelativePivot * dg[k]) || !(p > floor)) return false;
  }
  const int rest = M - F;
  if (rest == 0) return true;
  const double one = 1.0, minus_one = -1.0;
  double* below = A + F;  // rows F..M−1 of the first F columns
  dtrsm_("R", "L", "T", "N", &rest, &F, &one, A, &lda, below, &lda, 1, 1, 1, 1);
  double* trailing = A + F + static_cast<size_t>(F) * lda;
  dsyrk_("L", "N", &rest, &F, &minus_one, below, &lda, &one, trailing, &lda, 1, 1);
  for (int k = 0; k < F; ++k) {
    const double* col = below + static_cast<size_t>(k) * lda;
    for (int i = 0; i < rest; ++i)
      if (!std::isfinite(col[i])) return false;
  }
  return true;
}

// Cliques up to this order use the simple left-looking loop, larger ones the blocked kernels.
constexpr int kSmallCliqueOrder = 72;

}  // namespace

bool partialCholesky(double* A, int lda, int F, int M, const double* dg) {
  return M <= kSmallCliqueOrder ? partialCholeskySmall(A, lda, F, M, dg)
                                : partialCholeskyBlocked(A, lda, F, M, dg);
}

void partialCholeskyUpdate(double* L, int ldl, int N, int F, double* d, double* W, int ldw, int k) {
  for (int j = 0; j < F; ++j) {
    double* Lj = L + static_cast<size_t>(j) * ldl;
    for (int t = 0; t < k; ++t) {
      double* w = W + static_cast<size_t>(t) * ldw;
      const double wj = w[j];
      if (wj == 0.0) continue;  // column j is unchanged by this vector
      const double ljj = Lj[j];
      const double r = std::sqrt(ljj * ljj + wj * wj);
      const double c = r / ljj, s = wj / ljj, inv_c = ljj / r;
      Lj[j] = r;
      for (int i = j + 1; i < N; ++i) {
        const double l = (Lj[i] + s * w[i]) * inv_c;
        w[i] = c * w[i] - s * l;
        Lj[i] = l;
      }
      const double dj = (d[j] + s * w[N]) * inv_c;
      w[N] = c * w[N] - s * dj;
      d[j] = dj;
      w[j] = 0.0;
    }
  }
}

}  // namespace arbor::bayestree
