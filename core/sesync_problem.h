// The data matrices of SE-Sync (Rosen, Carlone, Bandeira, Leonard, "SE-Sync: a certifiably
// correct algorithm for synchronization over the special Euclidean group", IJRR 2019, §4):
// isotropic precisions κ, τ per edge, the connection Laplacian L(G̃ρ), the translational
// Laplacian L(W^τ), Ṽ, Σ̃, the full data matrix M (eq. 15) and the rotation-only quadratic
// form Q = L(G̃ρ) + Σ̃ − Ṽᵀ L(W^τ)† Ṽ (eq. 20, translations eliminated analytically), applied
// as an operator through a sparse Cholesky factor of L(W^τ) with node 0 removed.
//
// Conventions (column form): a point of the relaxation is X ∈ ℝ^{dn×r}, block Xᵢ = X.rows(d·i,
// d) = Yᵢᵀ with Yᵢ ∈ St(d, r) of the paper, so Xᵢ Xᵢᵀ = I_d; the objective is tr(Xᵀ Q X).
// At rank r = d, Xᵢ = Rᵢᵀ.
#pragma once

#include <memory>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "arbor_slam/core/pose_graph.h"

namespace arbor {

/// One relative measurement in SE-Sync's form: x_j ≈ x_i · (R, t), weights κ (rotation, on
/// ‖R_j − R_i R‖²_F) and τ (translation, on ‖t_j − t_i − R_i t‖²).
struct SESyncMeasurement {
  int i = 0, j = 0;
  Eigen::MatrixXd R;
  Eigen::VectorXd t;
  double kappa = 1, tau = 1;
};

/// The measurements of a pose graph. Ω of each edge is replaced by isotropic precisions from
/// isotropicInformation (core/information.h): τ = d / tr(Ω_tt⁻¹) and ω = r / tr(Ω_rr⁻¹), the
/// precision on our rotational error θ (2D) or 2·vec q ≈ θ (3D). κ is SE-Sync's reader's: in 3D
/// κ = ω / 2 = 3 / (2 tr(Ω_rr⁻¹)), which makes κ‖R − R Exp(θ)‖²_F ≈ ω‖θ‖² (our F to second
/// order, since ‖R − R Exp(θ)‖²_F ≈ 2‖θ‖²); in 2D κ = Ω_θθ = ω, twice that weight. (With ω / 2 in
/// 2D the relaxation was not exact on M3500c and needed rank 6 on M3500b; with SE-Sync's κ it is
/// exact on M3500c. The polish after rounding is in our F either way.) Self-loops are
/// dropped (their cost does not depend on the poses). Throws std::invalid_argument if the
/// graph is not connected (naming the first pose id not reached from the first pose) or has
/// priors (requireRelativePoseEdgesOnly).
template <class G>
std::vector<SESyncMeasurement> sesyncMeasurements(const PoseGraph<G>& graph);

/// SE-Sync's model is relative-pose measurements with a free gauge: the certifiable solver
/// refuses a graph with pose or position priors (std::invalid_argument: "the certifiable solver
/// takes relative-pose edges only: N pose priors, M position priors; use --solver lm"). Pose
/// priors could enter as edges to an extra anchor pose held at the identity, but position
/// priors have no place in the model, and an isotropic anchor edge would certify a problem other
/// than the one the polish solves; the batch solvers take every factor.
template <class G>
void requireRelativePoseEdgesOnly(const PoseGraph<G>& graph);

/// Which matrix the regularised-Cholesky preconditioner factors, P + λI with
/// λ = ‖P‖ / (max_condition − 1) so that its condition number is at most max_condition (SE-Sync
/// uses M and 10⁶; L(G̃ρ) with 10⁵ took the fewest tCG steps on the shared datasets).
enum class SESyncPreconditioner {
  kConnectionLaplacian,  ///< L(G̃ρ) + λI (dn × dn): cheaper, and fewer tCG steps on our sets
  kDataMatrix,  ///< M + λI, the Schur-complement form SE-Sync 1.0 uses (≈ (Q + λI)⁻¹)
};

/// The data matrices and factorisations of one SE-Sync problem.
class SESyncProblem {
 public:
  /// n poses of dimension d (2 or 3). Throws std::invalid_argument on bad indices, a
  /// disconnected measurement graph or non-positive weights, std::runtime_error if a
  /// factorisation fails.
  SESyncProblem(int n, int d, const std::vector<SESyncMeasurement>& measurements,
                SESyncPreconditioner preconditioner = SESyncPreconditioner::kConnectionLaplacian,
                double max_condition = 1e5);
  ~SESyncProblem();
  SESyncProblem(const SESyncProblem&) = delete;
  SESyncProblem& operator=(const SESyncProblem&) = delete;

  int numPoses() const { return n_; }
  int dim() const { return d_; }

  /// Q X for X ∈ ℝ^{dn×k} (any k).
  Eigen::MatrixXd Q(const Eigen::MatrixXd& X) const;
  /// tr(Xᵀ Q X).
  double objective(const Eigen::MatrixXd& X) const;
  /// The regularised-Cholesky preconditioner applied to V (dn × k): (L(G̃ρ) + λI)⁻¹ V, or the
  /// rotational block of (M + λI)⁻¹ [0; V] (the inverse of the Schur complement of M + λI).
  Eigen::MatrixXd precondition(const Eigen::MatrixXd& V) const;

  /// The d×d blocks of Λ(X) = SymBlockDiag(Q X Xᵀ) (eq. 119), side by side: d × dn. QX = Q X.
  Eigen::MatrixXd lambdaBlocks(const Eigen::MatrixXd& X, const Eigen::MatrixXd& QX) const;
  /// (Q − Λ) x for a vector x ∈ ℝ^{dn}.
  Eigen::VectorXd certificateProduct(const Eigen::MatrixXd& lambda_blocks,
                                     const Eigen::VectorXd& x) const;

  /// Fast verification as in SE-Sync: tries a Cholesky factorisation of S + ηI, S = M −
  /// blkdiag(0, Λ) the certificate of the translation-explicit problem (S ⪰ 0 ⇔ Q − Λ ⪰ 0).
  /// On success returns true and sets *lambda_min to λ_min(S) from a few shift-invert Lanczos
  /// steps on (S + ηI)⁻¹. Otherwise returns false; S + σI is factored for σ = 10η, 100η, …
  /// until it is positive definite, shift-invert Lanczos then gives *lambda_min = λ_min(S) and
  /// *direction = the rotational part of its eigenvector, normalised (a direction of negative
  /// curvature of Q − Λ: its Rayleigh quotient there is ≤ λ_min(S) < 0), or an empty vector if
  /// that failed.
  bool verifyFullCertificate(const Eigen::MatrixXd& lambda_blocks, double eta, double* lambda_min,
                             Eigen::VectorXd* direction = nullptr) const;

  /// Translations minimising the cost for the rotations R (dn × d, block i = Rᵢᵀ): n × d,
  /// row i = tᵢᵀ, with t₀ = 0.
  Eigen::MatrixXd recoverTranslations(const Eigen::MatrixXd& R) const;

  const Eigen::SparseMatrix<double>& connectionLaplacian() const { return L_rho_; }
  const Eigen::SparseMatrix<double>& dataMatrix() const { return M_; }

 private:
  struct Factors;
  int n_ = 0, d_ = 0;
  Eigen::SparseMatrix<double> L_rho_;        // L(G̃ρ), dn × dn
  Eigen::SparseMatrix<double> L_rho_sigma_;  // L(G̃ρ) + Σ̃
  Eigen::SparseMatrix<double> V_red_;        // Ṽ without row 0, (n−1) × dn
  Eigen::SparseMatrix<double> V_red_t_;      // its transpose
  Eigen::SparseMatrix<double> M_;            // full data matrix, (n + dn)², lower + upper
  SESyncPreconditioner preconditioner_;
  std::unique_ptr<Factors> factors_;
};

}  // namespace arbor
