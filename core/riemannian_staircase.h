// SE-Sync's certifiable solver (Rosen, Carlone, Bandeira, Leonard, IJRR 2019, Algorithm 2):
// the Riemannian staircase over St(d, r)ⁿ, each level solved by a Riemannian trust-region
// method with Steihaug–Toint truncated conjugate gradients (Absil, Baker, Gallivan 2007),
// the optimality certificate S = Q − Λ(Y) (§4.2), second-order saddle escape (§4.1.2),
// rounding to SO(d)ⁿ with translation recovery (Algorithm 3) and a short LM polish of the full
// (anisotropic-Ω) objective F = Σ eᵀΩe.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "arbor_slam/core/batch_solver.h"
#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/core/sesync_problem.h"

namespace arbor {

struct RtrOptions {
  int initial_rank = 5;  ///< r₀ (SE-Sync default)
  int max_rank = 10;     ///< r_max (SE-Sync default)
  /// Stop a level when ‖grad f‖ (Frobenius, absolute, as SE-Sync) is below this.
  double gradient_tolerance = 1e-2;
  /// … or when the preconditioned gradient's norm is below this (absolute, SE-Sync 1e-4).
  double preconditioned_gradient_tolerance = 1e-4;
  /// … or when an accepted step lowers f by less than this fraction (SE-Sync 1e-7).
  double relative_decrease_tolerance = 1e-7;
  /// … or when an accepted step is shorter than this (Frobenius, SE-Sync 1e-3).
  double step_tolerance = 1e-3;
  int max_iterations = 1000;       ///< trust-region iterations per level
  int max_tcg_iterations = 10000;  ///< inner tCG iterations per trust-region iteration
  double tcg_kappa = 0.1;          ///< tCG stops at ‖r‖ ≤ ‖r₀‖ min(‖r₀‖^θ, κ)
  double tcg_theta = 0.5;
  /// η: the certificate accepts λ_min(S) ≥ −η (S + ηI must factor, as SE-Sync's fast
  /// verification; absolute; 1e-4 as SE-Sync's min_eig_num_tol. With 1e-5, M3500b's rank-5
  /// point, λ_min = −2.7e-5, which SE-Sync certifies, sent the staircase to rank 6).
  double certificate_tolerance = 1e-4;
  /// Exactness: suboptimality_bound ≤ this × |f(Y)| (the SDP solution has rank d).
  double relative_gap_tolerance = 1e-4;
  /// L(G̃ρ) + λI by default; SE-Sync's C++ default (Schur form of
  /// M + λI, with max condition 10⁶) on request.
  SESyncPreconditioner preconditioner = SESyncPreconditioner::kConnectionLaplacian;
  double preconditioner_max_condition = 1e5;  ///< regularisation λ = ‖P‖ / (this − 1)
  bool polish = true;                         ///< LM on the full objective after rounding
  BatchOptions polish_options = batchOptions(BatchMethod::kLevenbergMarquardt, 100, 1e-6);
  bool verbose = false;  ///< progress on stderr
  /// Checked before each trust-region and tCG iteration and between the staircase's steps; a
  /// cancelled solve rounds the last (accepted) staircase point, skips the certificate, runs
  /// the polish with this token (so it stops at once) and sets RtrSummary::cancelled. The
  /// polish uses this token, not polish_options.cancel.
  CancellationToken cancel = {};
};

struct RtrSummary {
  double sesync_objective = 0;  ///< tr(Q Yᵀ Y) at the last staircase point (relaxation value)
  double sesync_objective_initial = 0;  ///< … at the (lifted) chordal start; ≥ the first level's
  double F_rounded = 0;                 ///< F at the rounded estimate (before polish)
  double F_final = 0;                   ///< F after the polish (= F_rounded without it)
  int rank = 0;                         ///< the staircase level reached
  /// λ_min of the certificate at that level: of S = M − blkdiag(0, Λ) (translation-explicit
  /// form, by shift-invert Lanczos) when the relaxation is solved, else the curvature vᵀ(Q − Λ)v <
  /// 0 along the unit escape direction v found.
  double lambda_min = 0;
  /// f(rounded) − f(Y) in SE-Sync's objective: an upper bound on how far the rounded estimate is
  /// from the global optimum of SE-Sync's (isotropic) problem when the relaxation is solved.
  double suboptimality_bound = 0;
  /// The relaxation is solved (λ_min ≥ −certificate_tolerance) and exact: the rounded estimate
  /// is within relative_gap_tolerance of it, so it is SE-Sync's global optimum.
  bool certified = false;
  bool relaxation_solved = false;  ///< λ_min ≥ −certificate_tolerance (SE-Sync's "GlobalOpt")
  double time_problem_s = 0, time_optimization_s = 0, time_certificate_s = 0, time_rounding_s = 0,
         time_polish_s = 0, time_s = 0;
  int rtr_iterations = 0;  ///< trust-region iterations over all levels
  int tcg_iterations = 0;  ///< inner iterations (Hessian-vector products) over all levels
  bool cancelled = false;  ///< stopped by RtrOptions::cancel: an uncertified estimate
  std::string message;
};

/// Solves the pose graph with SE-Sync and writes the estimate (gauge: the first of
/// graph.gaugeIndices() keeps its file value when graph.has_initial_estimate, else identity;
/// other fixed poses are set to their file values before the polish). *poses is only written.
/// Throws std::invalid_argument on bad options, a null `poses`, a graph that is not
/// connected (naming a pose id), or a graph with priors (requireRelativePoseEdgesOnly in
/// core/sesync_problem.h: the certificate covers SE-Sync's relative-pose problem only, so
/// graphs with pose or position priors go to the batch solvers).
template <class G>
RtrSummary solveRtr(const PoseGraph<G>& graph, std::vector<G>* poses,
                    const RtrOptions& options = {});

struct MinimumEigenpair {
  double lambda_min = 0;
  Eigen::VectorXd vector;  ///< unit eigenvector in ℝ^{dn}
  bool converged = false;
};

/// λ_min(Q − Λ(X)) and its eigenvector for X ∈ St(d, r)ⁿ (dn × r, column form), by Lanczos
/// (Spectra) as SE-Sync's MATLAB code: the largest-magnitude eigenvalue λ_lm, then the
/// largest-magnitude eigenvalue of Q − Λ − 1.05 λ_lm I (whose spectrum is < 0). Throws
/// std::runtime_error if Lanczos fails, std::invalid_argument if X has the wrong shape.
MinimumEigenpair certificateMinimumEigenpair(const SESyncProblem& problem,
                                             const Eigen::MatrixXd& X);

/// λ_min(Q − Λ(X)) alone.
double certify(const SESyncProblem& problem, const Eigen::MatrixXd& X);

/// λ_min(S) at the rotations of `poses` (X = [Rᵢᵀ]): ≈ 0 (≥ −small) at a global optimum of the
/// relaxation, clearly negative at a point that is not one.
template <class G>
double certify(const PoseGraph<G>& graph, const std::vector<G>& poses);

}  // namespace arbor
