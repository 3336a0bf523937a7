#include "arbor_slam/bayestree/dense_kernels.h"

#include <cmath>

#include <algorithm>
#include <cstddef>

// LAPACK / BLAS (Fortran calling convention; the trailing arguments are the lengths of the
// character arguments, as gfortran passes them).
extern "C" {
void dpotrf_(const char* uplo, const int* n, double* a, const int* lda, int* info, std::size_t);
void dpotri_(const char* uplo, const int* n, double* a, const int* lda, int* info, std::size_t);
void dtrsm_(const char* side, const char* uplo, const char* transa, const char* diag, const int* m,
            const int* n, const double* alpha, const double* a, const int* lda, double* b,
            const int* ldb, std::size_t, std::size_t, std::size_t, std::size_t);
void dsyrk_(const char* uplo, const char* trans, const int* n, const int* k, const double* alpha,
            const double* a, const int* lda, const double* beta, double* c, const int* ldc,
            std::size_t, std::size_t);
}

// The hot loops below are compiled three times, for plain x86-64 (SSE2), AVX2/FMA and
// AVX-512, and the loader picks the widest the CPU has (as OpenBLAS does at run time): the
// project itself is built for any x86-64 (ARBOR_NATIVE off). `flatten` inlines the helpers
// into each copy. Not under ThreadSanitizer: the loader runs the copies' resolver before TSan's
// runtime is up, and the program crashes at start.
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && !defined(__SANITIZE_THREAD__)
#define ARBOR_VECTOR_CLONES \
  __attribute__((target_clones("default", "arch=x86-64-v3", "arch=x86-64-v4"), flatten))
#else
#define ARBOR_VECTOR_CLONES
#endif

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
ARBOR_VECTOR_CLONES
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

namespace {

// One rotation of the rank-one update on one row: the factor's entry l and the vector's entry
// *w become (l + s·w)/c and c·w − s·(new l); returns the new l.
inline double rotate(double l, double* w, double s, double inv_c, double c) {
  const double wi = *w;
  l = (l + s * wi) * inv_c;
  *w = c * wi - s * l;
  return l;
}

// Rows `begin`..`end`−1 of column `l` through K Givens-like rotations in turn (one sweep: each
// row's entry passes the K vectors' rotations while it is in a register).
template <int K>
void rotateRows(double* l, double* const* w, const double* s, const double* inv_c, const double* c,
                int begin, int end) {
  double* wp[K];
  double sa[K], ia[K], ca[K];
  for (int a = 0; a < K; ++a) {
    wp[a] = w[a];
    sa[a] = s[a];
    ia[a] = inv_c[a];
    ca[a] = c[a];
  }
#pragma GCC ivdep
  for (int i = begin; i < end; ++i) {
    double li = l[i];
    for (int a = 0; a < K; ++a) li = rotate(li, wp[a] + i, sa[a], ia[a], ca[a]);
    l[i] = li;
  }
}

void rotateRowsAny(double* l, double* const* w, const double* s, const double* inv_c,
                   const double* c, int count, int begin, int end) {
  switch (count) {
    case 1:
      return rotateRows<1>(l, w, s, inv_c, c, begin, end);
    case 2:
      return rotateRows<2>(l, w, s, inv_c, c, begin, end);
    case 3:
      return rotateRows<3>(l, w, s, inv_c, c, begin, end);
    case 6:
      return rotateRows<6>(l, w, s, inv_c, c, begin, end);
    default:
      for (int a = 0; a < count; ++a) rotateRows<1>(l, w + a, s + a, inv_c + a, c + a, begin, end);
  }
}

}  // namespace

bool inverseFromCholesky(double* A, int lda, int n) {
  if (n == 0) return true;
  int info = 0;
  dpotri_("L", &n, A, &lda, &info, 1);
  return info == 0;
}

void lowerRankUpdate(double* C, int ldc, int n, const double* A, int lda, int k) {
  if (n == 0 || k == 0) return;
  const double one = 1.0;
  dsyrk_("L", "N", &n, &k, &one, A, &lda, &one, C, &ldc, 1, 1);
}

ARBOR_VECTOR_CLONES
void partialCholeskyUpdate(double* L, int ldl, int N, int F, double* d, double* W, int ldw, int k) {
  constexpr int kMax = 16;
  double* w[kMax];
  double s[kMax], c[kMax], inv_c[kMax];
  for (int t0 = 0; t0 < k; t0 += kMax) {  // at most kMax vectors per sweep
    const int kt = std::min(kMax, k - t0);
    for (int j = 0; j < F; ++j) {
      double* Lj = L + static_cast<size_t>(j) * ldl;
      // The rotations of column j, in turn: those of vectors with a zero in row j are identities.
      int count = 0;
      double ljj = Lj[j];
      for (int t = t0; t < t0 + kt; ++t) {
        double* wt = W + static_cast<size_t>(t) * ldw;
        const double wj = wt[j];
        if (wj == 0.0) continue;
        const double r = std::sqrt(ljj * ljj + wj * wj);
        c[count] = r / ljj;
        s[count] = wj / ljj;
        inv_c[count] = ljj / r;
        w[count] = wt;
        ++count;
        ljj = r;
        wt[j] = 0.0;
      }
      if (count == 0) continue;
      Lj[j] = ljj;
      rotateRowsAny(Lj, w, s, inv_c, c, count, j + 1, N);
      // The right-hand side's row (d, kept apart from L: row N of W), rotated the same way.
      for (int a = 0; a < count; ++a) d[j] = rotate(d[j], w[a] + N, s[a], inv_c[a], c[a]);
    }
  }
}

namespace {

// Σ a_r b_r over n entries, in eight running sums (vectorisable without reassociating).
inline double dot(const double* a, const double* b, int n) {
  double acc[8] = {0, 0, 0, 0, 0, 0, 0, 0};
  int r = 0;
  for (; r + 8 <= n; r += 8)
    for (int u = 0; u < 8; ++u) acc[u] += a[r + u] * b[r + u];
  for (; r < n; ++r) acc[0] += a[r] * b[r];
  return ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]));
}

}  // namespace

ARBOR_VECTOR_CLONES
void solveConditional(const double* LS, int ld, int N, int F, const double* d, double* z) {
  for (int i = F - 1; i >= 0; --i) {
    const double* col = LS + static_cast<size_t>(i) * ld;
    z[i] = (d[i] - dot(col + i + 1, z + i + 1, N - i - 1)) / col[i];
  }
}

}  // namespace arbor::bayestree
