// Information matrices Ω of relative-pose measurements: validation, repair, isotropic form.
#pragma once

#include <string>

#include <Eigen/Core>

namespace arbor {

/// The largest |entry| accepted in an information matrix. Beyond it, eᵀΩe can overflow double
/// precision within a few steps of an estimate (with translations up to kMaxTranslation,
/// core/relative_pose_factor.h, one edge's cost stays below ~1e60). Real data is far below:
/// the shared datasets reach 3.2e8.
inline constexpr double kMaxInformationEntry = 1e30;

/// Why Ω cannot be used as an information matrix, or "" when it can: it must be finite, no
/// entry larger than kMaxInformationEntry in magnitude, symmetric (to 1e-9 relative) and
/// positive definite (a Cholesky factorisation exists).
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
