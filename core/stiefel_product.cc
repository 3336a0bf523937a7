#include "arbor_slam/core/stiefel_product.h"

#include <cmath>
#include <stdexcept>

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>

namespace arbor::stiefel {

namespace {

// The loops below with the block height D fixed at compile time (no temporaries on the heap).
template <int D>
void projectBlocks(const Eigen::MatrixXd& X, const Eigen::MatrixXd& V, Eigen::MatrixXd* out) {
  using Block = Eigen::Matrix<double, D, Eigen::Dynamic>;
  using Small = Eigen::Matrix<double, D, D>;
  const Eigen::Index n = X.rows() / D;
  Block Xi(D, X.cols()), Vi(D, X.cols());
  for (Eigen::Index i = 0; i < n; ++i) {
    Xi = X.middleRows<D>(D * i);
    Vi = V.middleRows<D>(D * i);
    const Small P = Vi * Xi.transpose();
    const Small S = 0.5 * (P + P.transpose());
    Vi.noalias() -= S * Xi;
    out->middleRows<D>(D * i) = Vi;
  }
}

template <int D>
void retractBlocks(Eigen::MatrixXd* A) {
  using Block = Eigen::Matrix<double, D, Eigen::Dynamic>;
  using Small = Eigen::Matrix<double, D, D>;
  const Eigen::Index n = A->rows() / D;
  Block Ai(D, A->cols());
  Eigen::SelfAdjointEigenSolver<Small> eig;
  for (Eigen::Index i = 0; i < n; ++i) {
    Ai = A->middleRows<D>(D * i);
    eig.compute(Ai * Ai.transpose());
    const Small inv_sqrt =
        eig.eigenvectors() *
        eig.eigenvalues().cwiseMax(1e-300).cwiseSqrt().cwiseInverse().asDiagonal() *
        eig.eigenvectors().transpose();
    A->middleRows<D>(D * i) = inv_sqrt * Ai;
  }
}

template <int D>
void multiplyBlocks(const Eigen::MatrixXd& blocks, const Eigen::MatrixXd& V, Eigen::MatrixXd* out) {
  using Block = Eigen::Matrix<double, D, Eigen::Dynamic>;
  const Eigen::Index n = V.rows() / D;
  Block Vi(D, V.cols()), Oi(D, V.cols());
  for (Eigen::Index i = 0; i < n; ++i) {
    Vi = V.middleRows<D>(D * i);
    const Eigen::Matrix<double, D, D> B = blocks.middleCols<D>(D * i);
    Oi.noalias() = B * Vi;
    out->middleRows<D>(D * i) = Oi;
  }
}

void checkDim(int d) {
  if (d != 2 && d != 3) throw std::invalid_argument("stiefel: block height must be 2 or 3");
}

}  // namespace

Eigen::MatrixXd project(const Eigen::MatrixXd& X, const Eigen::MatrixXd& V, int d) {
  checkDim(d);
  Eigen::MatrixXd out(V.rows(), V.cols());
  if (d == 2) {
    projectBlocks<2>(X, V, &out);
  } else {
    projectBlocks<3>(X, V, &out);
  }
  return out;
}

Eigen::MatrixXd retract(const Eigen::MatrixXd& X, const Eigen::MatrixXd& V, int d) {
  checkDim(d);
  Eigen::MatrixXd out = X + V;
  if (d == 2) {
    retractBlocks<2>(&out);
  } else {
    retractBlocks<3>(&out);
  }
  return out;
}

Eigen::MatrixXd blockMultiply(const Eigen::MatrixXd& blocks, const Eigen::MatrixXd& V, int d) {
  checkDim(d);
  Eigen::MatrixXd out(V.rows(), V.cols());
  if (d == 2) {
    multiplyBlocks<2>(blocks, V, &out);
  } else {
    multiplyBlocks<3>(blocks, V, &out);
  }
  return out;
}

Eigen::MatrixXd projectToSO(const Eigen::MatrixXd& A) {
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(A, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::MatrixXd U = svd.matrixU();
  const Eigen::MatrixXd& W = svd.matrixV();
  if ((U * W.transpose()).determinant() < 0) U.col(U.cols() - 1) *= -1.0;
  return U * W.transpose();
}

}  // namespace arbor::stiefel
