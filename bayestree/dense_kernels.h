// Dense kernels of the clique elimination: a non-zeroing growable buffer, the partial
// Cholesky factorisation of a clique's Hessian and its rank-k update (Kaess et al. 2012 §3: a
// clique's conditional and the factor it passes to its parent are one partial factorisation of its
// dense Hessian).
#pragma once

#include <algorithm>
#include <cstddef>
#include <memory>
#include <utility>

namespace arbor::bayestree {

// A growable array of doubles that, unlike std::vector, does not zero what it adds.
class DoubleBuffer {
 public:
  DoubleBuffer() = default;
  DoubleBuffer(const DoubleBuffer& o) : size_(o.size_), capacity_(o.size_) {
    if (size_) {
      data_.reset(new double[size_]);
      std::copy(o.data_.get(), o.data_.get() + size_, data_.get());
    }
  }
  DoubleBuffer& operator=(const DoubleBuffer& o) {
    if (this != &o) *this = DoubleBuffer(o);
    return *this;
  }
  DoubleBuffer(DoubleBuffer&&) noexcept = default;
  DoubleBuffer& operator=(DoubleBuffer&&) noexcept = default;

  /// Resizes without initialising; grows geometrically, never shrinks.
  void resize(size_t size) {
    if (size > capacity_) {
      size_t capacity = std::max<size_t>(64, capacity_);
      while (capacity < size) capacity *= 2;
      data_.reset(new double[capacity]);
      capacity_ = capacity;
    }
    size_ = size;
  }
  /// Resizes without initialising to exactly what is needed: reallocates when `size` exceeds
  /// the capacity or is below half of it (a clique's storage is sized once per elimination, so
  /// geometric growth and never shrinking would let recycled cliques hoard memory).
  void fit(size_t size) {
    if (size > capacity_ || size < capacity_ / 2) {
      data_.reset(size ? new double[size] : nullptr);
      capacity_ = size;
    }
    size_ = size;
  }
  size_t size() const { return size_; }
  size_t capacity() const { return capacity_; }
  void swap(DoubleBuffer& o) noexcept {
    data_.swap(o.data_);
    std::swap(size_, o.size_);
    std::swap(capacity_, o.capacity_);
  }
  double* data() { return data_.get(); }
  const double* data() const { return data_.get(); }
  double* begin() { return data_.get(); }
  double* end() { return data_.get() + size_; }

 private:
  std::unique_ptr<double[]> data_;
  size_t size_ = 0, capacity_ = 0;
};

/// Partial Cholesky of the lower triangle of the M×M column-major matrix A (leading dimension
/// lda): factors the first F columns in place (L, and below it [Sᵀ; dᵀ] = A_(s,g)f L⁻ᵀ) and
/// leaves the Schur complement in the trailing lower triangle. Returns false when a pivot p
/// (= L_kk²) is not safely positive: p ≤ 1e-10·dg[k] or p ≤ 1e-14·max(dg), with dg the diagonal
/// of A_ff before factorisation (the clique is then indeterminate). Small matrices use a simple
/// left-looking loop, large ones LAPACK/BLAS (dpotrf, dtrsm, dsyrk; OpenBLAS where installed).
bool partialCholesky(double* A, int lda, int F, int M, const double* dg);

/// C += A Aᵀ on the lower triangle of the n×n column-major C (leading dimension ldc), A n×k
/// (leading dimension lda): BLAS dsyrk.
void lowerRankUpdate(double* C, int ldc, int n, const double* A, int lda, int k);

/// (L Lᵀ)⁻¹ from its lower Cholesky factor L, in place on the lower triangle of the n×n
/// column-major A (leading dimension lda; the strict upper triangle is not touched): LAPACK's
/// dpotri, 2n³/3 flops. Returns false when L is singular (a zero on its diagonal).
bool inverseFromCholesky(double* A, int lda, int n);

/// Back-substitution of one conditional R x_f + S x_s = d, stored as LS = [L; Sᵀ] (N×F,
/// column-major, leading dimension ld) with R = Lᵀ: z = [x_f; x_s] (N entries), x_s given in
/// z[F..N), x_f written to z[0..F): x_i = (d_i − LS(i+1..N, i)ᵀ z(i+1..N)) / L_ii, from the last
/// frontal up.
void solveConditional(const double* LS, int ld, int N, int F, const double* d, double* z);

/// Rank-k update of a partial Cholesky factor (the rank-one update of Golub & Van Loan §6.5.4,
/// applied column by column for k vectors at once). `L` (N×F, column-major, leading dimension
/// ldl ≥ N) and `d` (F) are the first F columns of the factor of an (N+1)×(N+1) matrix M, `d` being
/// its last row; they become those of M + WWᵀ, with W (N+1)×k (leading dimension ldw, rows in
/// the same order). On return rows F..N of W hold V with Schur(M + WWᵀ) = Schur(M) + VVᵀ (the
/// update the factor passed on to the parent receives); rows 0..F−1 are destroyed.
void partialCholeskyUpdate(double* L, int ldl, int N, int F, double* d, double* W, int ldw, int k);

}  // namespace arbor::bayestree
