#include "bayestree/dense_kernels.h"

#include <cmath>

#include <Eigen/Cholesky>
#include <Eigen/Core>

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

// As partialCholeskySmall, with Eigen's cache-blocked LLT, triangular solve and rank update
// (for large cliques): L = chol(A_ff); [Sᵀ; dᵀ] = A_(s,g)f L⁻ᵀ; A_(s,g)(s,g) −= [Sᵀ; dᵀ][S d].
bool partialCholeskyBlocked(double* A, int lda, int F, int M, const double* dg) {
  Eigen::Map<Eigen::MatrixXd, 0, Eigen::OuterStride<>> full(A, M, M, Eigen::OuterStride<>(lda));
  Eigen::Ref<Eigen::MatrixXd, 0, Eigen::OuterStride<>> Aff = full.topLeftCorner(F, F);
  Eigen::LLT<Eigen::Ref<Eigen::MatrixXd, 0, Eigen::OuterStride<>>> llt(Aff);
  if (llt.info() != Eigen::Success) return false;
  double max_diag = 0;
  for (int k = 0; k < F; ++k) max_diag = std::max(max_diag, dg[k]);
  const double floor = kCliquePivot * max_diag;
  for (int k = 0; k < F; ++k) {
    const double p = Aff(k, k) * Aff(k, k);
    if (!std::isfinite(p) || !(p > kRelativePivot * dg[k]) || !(p > floor)) return false;
  }
  const int rest = M - F;
  if (rest == 0) return true;
  auto below = full.bottomLeftCorner(rest, F);
  Aff.transpose().template triangularView<Eigen::Upper>().template solveInPlace<Eigen::OnTheRight>(
      below);
  full.bottomRightCorner(rest, rest)
      .template selfadjointView<Eigen::Lower>()
      .rankUpdate(below, -1.0);
  return below.allFinite();
}

// Cliques up to this order use the simple left-looking loop, larger ones the blocked kernels.
constexpr int kSmallCliqueOrder = 72;

}  // namespace

bool partialCholesky(double* A, int lda, int F, int M, const double* dg) {
  return M <= kSmallCliqueOrder ? partialCholeskySmall(A, lda, F, M, dg)
                                : partialCholeskyBlocked(A, lda, F, M, dg);
}

}  // namespace arbor::bayestree
