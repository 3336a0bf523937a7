// The product of Stiefel manifolds St(d, r)ⁿ in column form (Absil, Mahony, Sepulchre,
// "Optimization Algorithms on Matrix Manifolds", 2008, §3.6 and §4.8; SE-Sync §4.1): a point is
// X ∈ ℝ^{dn×r} whose d×r blocks Xᵢ = X.middleRows(d·i, d) have orthonormal rows (Xᵢ Xᵢᵀ = I).
#pragma once

#include <Eigen/Core>

namespace arbor::stiefel {

/// d must be 2 or 3 (std::invalid_argument otherwise).

/// Orthogonal projection onto the tangent space at X: Vᵢ − sym(Vᵢ Xᵢᵀ) Xᵢ.
Eigen::MatrixXd project(const Eigen::MatrixXd& X, const Eigen::MatrixXd& V, int d);

/// Polar retraction: each block Xᵢ + Vᵢ mapped to its nearest matrix with orthonormal rows,
/// ((Xᵢ+Vᵢ)(Xᵢ+Vᵢ)ᵀ)^{-1/2} (Xᵢ+Vᵢ).
Eigen::MatrixXd retract(const Eigen::MatrixXd& X, const Eigen::MatrixXd& V, int d);

/// Blockwise product with d×d blocks B (d × dn, side by side): out_i = Bᵢ Vᵢ.
Eigen::MatrixXd blockMultiply(const Eigen::MatrixXd& blocks, const Eigen::MatrixXd& V, int d);

/// The nearest rotation (det +1) to a d×d matrix, by SVD.
Eigen::MatrixXd projectToSO(const Eigen::MatrixXd& A);

}  // namespace arbor::stiefel
