// The Ceres baseline of the benchmark (never linked into Arbor's libraries): the same
// objective F = Σ eᵀΩe in our convention (δ = z⁻¹xᵢ⁻¹xⱼ, e = [t(δ); wrap θ(δ)] or
// [t(δ); 2·vec q(δ)]; pose priors as that residual with xᵢ = I and xⱼ = x o, position priors
// t(x) − p, as core/prior_factors.h), autodiff cost functions, solved with the paper's settings:
// LEVENBERG_MARQUARDT, SPARSE_NORMAL_CHOLESKY, 100 iterations, function tolerance 1e-5, 1 thread.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "arbor_slam/core/pose_graph.h"

namespace arbor::bench {

struct CeresResult {
  double F_initial = 0;
  double F_final = 0;  ///< 2 × Ceres' own cost (which is ½F)
  int iterations = 0;
  std::string termination;  ///< CONVERGENCE, NO_CONVERGENCE or FAILURE
  double time_s = 0;        ///< Ceres' total time (problem set-up excluded)
};

/// Ceres' ceres::Covariance (SPARSE_QR) of every pose of a 2D graph at `poses`, the poses of
/// `fixed` held constant (zero covariance), in Arbor's tangent x ⊞ τ = (t + R v, θ + ω): Ceres'
/// parameters are (t, θ) in the world frame, so Σ = J Σ_Ceres Jᵀ with J = diag(Rᵀ, 1), exact
/// for the linearised system. *time_s: Ceres' Compute and the block reads. Throws
/// std::runtime_error if Ceres cannot compute it (a rank-deficient system).
std::vector<Eigen::Matrix3d> ceresCovariances(const PoseGraph<SE2>& graph,
                                              const std::vector<SE2>& poses,
                                              const std::vector<int>& fixed, double* time_s);

/// Ceres' joint covariance [[Σ_aa, Σ_ab], [Σ_ba, Σ_bb]] of each pose pair (a, b) of `pairs`
/// (dense indices of a 2D graph; a ≠ b, neither in `fixed`), as ceresCovariances (SPARSE_QR, one
/// thread, `fixed` constant, in Arbor's tangent), computing only the blocks the pairs need.
/// Throws std::runtime_error if Ceres cannot compute it.
std::vector<Eigen::Matrix<double, 6, 6>> ceresJointCovariances(
    const PoseGraph<SE2>& graph, const std::vector<SE2>& poses, const std::vector<int>& fixed,
    const std::vector<std::pair<int, int>>& pairs);

template <class G>
CeresResult solveWithCeres(const PoseGraph<G>& graph, std::vector<G>* poses,
                           int max_iterations = 100, double function_tolerance = 1e-5);

}  // namespace arbor::bench
