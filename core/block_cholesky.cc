#include "arbor_slam/core/block_cholesky.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace arbor {

template <int kBlock>
BlockCholesky<kBlock>::BlockCholesky(const std::vector<std::vector<int>>& lower) {
  const int n = static_cast<int>(lower.size());
  // Column j of L has the rows of A's column j and of its children in the elimination tree,
  // below j (the symbolic factorisation by row merging).
  std::vector<std::vector<int>> pattern(n), children(n);
  std::vector<int> mark(n, -1);
  for (int j = 0; j < n; ++j) {
    std::vector<int>& p = pattern[j];
    mark[j] = j;
    const auto add = [&](int i) {
      if (mark[i] != j) {
        mark[i] = j;
        p.push_back(i);
      }
    };
    for (int i : lower[j]) {
      if (i <= j || i >= n)
        throw std::invalid_argument("BlockCholesky: block (" + std::to_string(i) + ", " +
                                    std::to_string(j) + ") is not below the diagonal of a " +
                                    std::to_string(n) + "-block matrix");
      add(i);
    }
    for (int c : children[j])
      for (int i : pattern[c])
        if (i > j) add(i);
    std::sort(p.begin(), p.end());
    if (!p.empty()) children[p.front()].push_back(j);  // the parent is the first row below j
  }
  column_start_.assign(n + 1, 0);
  for (int j = 0; j < n; ++j)
    column_start_[j + 1] = column_start_[j] + static_cast<int>(pattern[j].size());
  rows_.reserve(column_start_[n]);
  for (const auto& p : pattern) rows_.insert(rows_.end(), p.begin(), p.end());
  diagonal_.assign(n, Block::Zero());
  off_diagonal_.assign(rows_.size(), Block::Zero());
}

template <int kBlock>
double BlockCholesky<kBlock>::nonzeros() const {
  return static_cast<double>(off_diagonal_.size()) * kBlock * kBlock +
         static_cast<double>(diagonal_.size()) * kBlock * (kBlock + 1) / 2;
}

template <int kBlock>
int BlockCholesky<kBlock>::find(int i, int j) const {
  if (j < 0 || j >= numBlocks()) return -1;
  const auto begin = rows_.begin() + column_start_[j], end = rows_.begin() + column_start_[j + 1];
  const auto it = std::lower_bound(begin, end, i);
  return it != end && *it == i ? static_cast<int>(it - rows_.begin()) : -1;
}

template <int kBlock>
void BlockCholesky<kBlock>::setOffDiagonalZero() {
  for (Block& b : off_diagonal_) b.setZero();
}

template <int kBlock>
bool BlockCholesky<kBlock>::factorize() {
  factorized_ = false;
  failed_block_ = -1;
  const int n = numBlocks();
  for (int j = 0; j < n; ++j) {
    // L_jj = chol(A_jj); the column below: L_kj = A_kj L_jj⁻ᵀ.
    Block& d = diagonal_[j];
    for (int c = 0; c < kBlock; ++c) {  // in-place unblocked Cholesky of the lower triangle
      const double pivot = d(c, c) - d.row(c).head(c).squaredNorm();
      if (!(pivot > 0.0) || !std::isfinite(pivot)) {
        failed_block_ = j;
        return false;
      }
      d(c, c) = std::sqrt(pivot);
      for (int r = c + 1; r < kBlock; ++r)
        d(r, c) = (d(r, c) - d.row(r).head(c).dot(d.row(c).head(c))) / d(c, c);
    }
    d.template triangularView<Eigen::StrictlyUpper>().setZero();
    const Block inverse_t =
        d.template triangularView<Eigen::Lower>().solve(Block::Identity()).transpose();
    const int begin = column_start_[j], end = column_start_[j + 1];
    for (int k = begin; k < end; ++k) off_diagonal_[k] = (off_diagonal_[k] * inverse_t).eval();
    // Schur complement: A_ab −= L_aj L_bjᵀ for rows a ≥ b of column j. Column j's rows below b
    // are all in column b's pattern, which is walked once in ascending order.
    for (int kb = begin; kb < end; ++kb) {
      const int b = rows_[kb];
      const Block& l_b = off_diagonal_[kb];
      diagonal_[b].noalias() -= l_b * l_b.transpose();
      int position = column_start_[b];
      for (int ka = kb + 1; ka < end; ++ka) {
        const int a = rows_[ka];
        while (rows_[position] != a) ++position;
        off_diagonal_[position].noalias() -= off_diagonal_[ka] * l_b.transpose();
      }
    }
  }
  factorized_ = true;
  return true;
}

template <int kBlock>
void BlockCholesky<kBlock>::solve(const Eigen::VectorXd& b, Eigen::VectorXd* x) const {
  if (!factorized_) throw std::logic_error("BlockCholesky::solve: no successful factorisation");
  const int n = numBlocks();
  if (b.size() != static_cast<Eigen::Index>(n) * kBlock)
    throw std::invalid_argument("BlockCholesky::solve: right-hand side of size " +
                                std::to_string(b.size()) + ", expected " +
                                std::to_string(n * kBlock));
  *x = b;
  // L y = b, then Lᵀ x = y.
  for (int j = 0; j < n; ++j) {
    auto xj = x->template segment<kBlock>(j * kBlock);
    diagonal_[j].template triangularView<Eigen::Lower>().solveInPlace(xj);
    for (int k = column_start_[j]; k < column_start_[j + 1]; ++k)
      x->template segment<kBlock>(rows_[k] * kBlock).noalias() -= off_diagonal_[k] * xj;
  }
  for (int j = n - 1; j >= 0; --j) {
    Vector t = x->template segment<kBlock>(j * kBlock);
    for (int k = column_start_[j]; k < column_start_[j + 1]; ++k)
      t.noalias() -= off_diagonal_[k].transpose() * x->template segment<kBlock>(rows_[k] * kBlock);
    diagonal_[j].transpose().template triangularView<Eigen::Upper>().solveInPlace(t);
    x->template segment<kBlock>(j * kBlock) = t;
  }
}

template class BlockCholesky<3>;
template class BlockCholesky<6>;

}  // namespace arbor
