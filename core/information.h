// Information matrices Ω of relative-pose measurements: validation, repair, isotropic form.
#pragma once

#include <string>

#include <Eigen/Core>

namespace arbor {

/// Why Ω cannot be used as an information matrix, or "" when it can: it must be finite,
/// symmetric (to 1e-9 relative) and positive definite (a Cholesky factorisation exists).
std::string informationProblem(const Eigen::MatrixXd& omega);

/// The nearest positive-definite matrix: eigenvalues clamped to at least
/// `relative_floor` × the largest absolute eigenvalue (and at least 1e-12).
Eigen::MatrixXd nearestPositiveDefinite(const Eigen::MatrixXd& omega, double relative_floor = 1e-6);

/// One translational and one rotational precision per edge, as SE-Sync forms them
/// (Rosen et al. 2019, §5): τ = d / tr(Ω_tt⁻¹), and for the rotation block r / tr(Ω_rr⁻¹),
/// r = 1 (2D) or 3 (3D); our rotational error is 2·vec q ≈ θ, so κ_ours = 2 κ_SE-Sync.
/// Throws std::invalid_argument if a block is not positive definite.
Eigen::MatrixXd isotropicInformation(const Eigen::MatrixXd& omega, int dim);

/// How a reader treats a measurement whose Ω fails `informationProblem`.
enum class InformationPolicy {
  kRefuse,     ///< error (the default)
  kRepair,     ///< replace by nearestPositiveDefinite
  kIsotropic,  ///< replace every Ω (good or bad) by isotropicInformation of its nearest PD
};

}  // namespace arbor
