// The weighted least-squares rigid alignment of point sets (Kabsch; Umeyama, "Least-squares
// estimation of transformation parameters between two point patterns", TPAMI 1991, without
// scale): the move that takes a component's estimate into its priors' frame.
#pragma once

#include <cmath>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <Eigen/SVD>

namespace arbor {

/// The rigid move T = (R, t) minimising Σ wₖ ‖R qₖ + t − pₖ‖²: with centroids q̄ = Σ wq / Σ w,
/// p̄ likewise, and C = Σ w (p − p̄)(q − q̄)ᵀ = U Σ Vᵀ, R = U diag(1, …, 1, det(U Vᵀ)) Vᵀ and
/// t = p̄ − R q̄. The identity when there is nothing to fit (Σ w = 0).
template <class G>
G rigidAlignment(const std::vector<typename G::Translation>& q,
                 const std::vector<typename G::Translation>& p, const std::vector<double>& w) {
  constexpr int d = G::kDim;
  using MatD = Eigen::Matrix<double, d, d>;
  using VecD = Eigen::Matrix<double, d, 1>;
  double W = 0;
  VecD q_mean = VecD::Zero(), p_mean = VecD::Zero();
  for (size_t k = 0; k < q.size(); ++k) {
    W += w[k];
    q_mean += w[k] * q[k];
    p_mean += w[k] * p[k];
  }
  if (!(W > 0)) return G::Identity();
  q_mean /= W;
  p_mean /= W;
  MatD C = MatD::Zero();
  for (size_t k = 0; k < q.size(); ++k) C += w[k] * (p[k] - p_mean) * (q[k] - q_mean).transpose();
  const Eigen::JacobiSVD<MatD> svd(C, Eigen::ComputeFullU | Eigen::ComputeFullV);
  MatD D = MatD::Identity();
  D(d - 1, d - 1) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1 : 1;
  const MatD R = svd.matrixU() * D * svd.matrixV().transpose();
  const VecD t = p_mean - R * q_mean;
  if constexpr (d == 2) {
    return G(t, std::atan2(R(1, 0), R(0, 0)));
  } else {
    return G(Eigen::Quaterniond(R).normalized(), t);
  }
}

}  // namespace arbor
