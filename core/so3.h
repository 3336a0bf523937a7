// SO(3) helpers on unit quaternions (Solà et al., "A micro Lie theory", §A–B).
// Tangent vectors are rotation vectors ω ∈ ℝ³; Jacobians are right Jacobians.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace arbor::so3 {

/// The skew-symmetric matrix [w]× with [w]× v = w × v.
Eigen::Matrix3d hat(const Eigen::Vector3d& w);

/// Exp: ℝ³ → SO(3) as a unit quaternion; optional right Jacobian Jr(ω).
Eigen::Quaterniond Exp(const Eigen::Vector3d& w, Eigen::Matrix3d* J_r = nullptr);

/// Log: SO(3) → ℝ³ (angle in [0, π]); optional inverse right Jacobian Jr⁻¹(Log q).
Eigen::Vector3d Log(const Eigen::Quaterniond& q, Eigen::Matrix3d* J_r_inv = nullptr);

/// Right Jacobian Jr(ω) of Exp and its inverse.
Eigen::Matrix3d rightJacobian(const Eigen::Vector3d& w);
Eigen::Matrix3d rightJacobianInverse(const Eigen::Vector3d& w);

/// The quaternion with non-negative scalar part (q and −q are the same rotation).
Eigen::Quaterniond canonical(const Eigen::Quaterniond& q);

}  // namespace arbor::so3
