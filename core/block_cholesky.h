// Sparse Cholesky LLᵀ of a symmetric positive-definite matrix made of dense kBlock×kBlock
// blocks (one per pose): right-looking ("fan-out") column Cholesky over block columns (Davis,
// Rajamanickam & Sid-Lakhdar, "A survey of direct methods for sparse linear systems", Acta
// Numerica 2016) with fixed-size Eigen kernels. On pose graphs it beats CHOLMOD on small
// factorisations, where CHOLMOD's simplicial and small-supernode paths pay per-entry and
// per-BLAS-call overheads, and loses on large ones (docs/design.md, "Why CHOLMOD from 1e8 flops").
#pragma once

#include <vector>

#include <Eigen/Core>

namespace arbor {

template <int kBlock>
class BlockCholesky {
 public:
  using Block = Eigen::Matrix<double, kBlock, kBlock>;

  /// Symbolic factorisation. lower[j] lists the block rows i > j of the nonzero blocks (i, j)
  /// of the matrix (any order, repeats allowed); the blocks should already be in a
  /// fill-reducing order. Throws std::invalid_argument on a row index out of range.
  explicit BlockCholesky(const std::vector<std::vector<int>>& lower);

  int numBlocks() const { return static_cast<int>(diagonal_.size()); }
  /// Scalar nonzeros of L.
  double nonzeros() const;

  /// Where block (i, j), i > j, of L lives in offDiagonal(); −1 if outside the pattern.
  int find(int i, int j) const;

  /// Loading the matrix: zero every off-diagonal block, then write the matrix's blocks
  /// (diagonal(j) the full symmetric block (j, j), offDiagonal(find(i, j)) the block (i, j)).
  void setOffDiagonalZero();
  Block& diagonal(int j) { return diagonal_[j]; }
  Block& offDiagonal(int k) { return off_diagonal_[k]; }

  /// Factors the loaded matrix in place. False if it is not (numerically) positive definite;
  /// failedBlock() then tells the block column.
  bool factorize();
  int failedBlock() const { return failed_block_; }

  /// x = A⁻¹ b with the last successful factorisation.
  void solve(const Eigen::VectorXd& b, Eigen::VectorXd* x) const;

 private:
  using Vector = Eigen::Matrix<double, kBlock, 1>;
  std::vector<int> column_start_;  // column j's off-diagonal blocks: [start[j], start[j + 1])
  std::vector<int> rows_;          // their block rows, ascending within a column
  std::vector<Block, Eigen::aligned_allocator<Block>> diagonal_;
  std::vector<Block, Eigen::aligned_allocator<Block>> off_diagonal_;
  int failed_block_ = -1;
  bool factorized_ = false;
};

extern template class BlockCholesky<3>;
extern template class BlockCholesky<6>;

}  // namespace arbor
