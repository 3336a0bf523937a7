// Sparse Cholesky LLᵀ of a symmetric positive-definite matrix stored as its upper triangle in
// compressed-column form, via CHOLMOD (Chen, Davis, Hager, Rajamanickam, ACM TOMS 35(3), 2008):
// symbolic analysis once, numeric factorisation as often as the values change.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace arbor {

/// The upper triangle (diagonal included) of an n×n symmetric matrix in compressed-column form,
/// row indices ascending within each column.
struct SymmetricPattern {
  int n = 0;
  std::vector<int> col_ptr;  ///< n + 1 entries
  std::vector<int> row_idx;  ///< col_ptr[n] entries
};

/// A fill-reducing symmetric ordering of `pattern` (postordered): order[k] is the old index
/// placed k-th. AMD; when AMD's factor needs more than `nested_dissection_flops` flops, also
/// METIS and CHOLMOD's nested dissection (better on large 3D graphs), keeping whichever of them
/// needs the fewest flops.
/// `flops`, if given, receives the flops of a Cholesky factorisation in that order.
std::vector<int> fillReducingOrdering(const SymmetricPattern& pattern,
                                      double nested_dissection_flops = 0.0,
                                      double* flops = nullptr);

/// LLᵀ factorisation in the natural order of the pattern (the caller orders the variables).
class SparseCholesky {
 public:
  /// Symbolic analysis of `pattern` (which must have every diagonal entry).
  explicit SparseCholesky(SymmetricPattern pattern);
  ~SparseCholesky();
  SparseCholesky(const SparseCholesky&) = delete;
  SparseCholesky& operator=(const SparseCholesky&) = delete;

  /// Numeric factorisation of the matrix whose values (col_ptr[n] of them, in pattern order)
  /// are `values`. Returns false when it is not (numerically) positive definite; failedColumn()
  /// then tells where.
  bool factorize(const double* values);
  /// x = A⁻¹ b with the last successful factorisation.
  void solve(const Eigen::VectorXd& b, Eigen::VectorXd* x);

  int failedColumn() const { return failed_column_; }
  /// Nonzeros of L and flops of one factorisation (from the analysis).
  double factorNonzeros() const;
  double factorFlops() const;

 private:
  struct Cholmod;
  SymmetricPattern pattern_;
  std::unique_ptr<Cholmod> cholmod_;
  int failed_column_ = -1;
  bool factorized_ = false;
};

}  // namespace arbor
