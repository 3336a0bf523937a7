// Robust batch solve of a pose graph with false loop closures: graduated non-convexity (GNC)
// over Levenberg–Marquardt, after Yang, Antonante, Tzoumas, Carlone, "Graduated Non-Convexity
// for Robust Spatial Perception", RA-L 2020, Algorithm 1, with the kernels of
// core/robust_kernel.h on each edge's s = eᵀΩe:
//
//   x⁰ = argmin Σ s_k(x)                      (plain least squares, every weight 1)
//   μ⁰ from s_max = max s_k(x⁰) over the weighted edges (RobustKernel::initialMu)
//   repeat:  w_k = ρ′_μ(s_k(x))               (the closed-form weight update; trusted: 1)
//            x = argmin Σ w_k s_k(x) + priors  (LM, warm-started: WeightedBatchSolver)
//            μ ← μ·1.4 (TLS) or μ/1.4 (GM)
//   until the weights are binary (TLS: no s_k in the transition band), stop changing, or the
//   iteration limit; then the inlier set {w_k > 0.5} is solved once more with weight 1
//   (the inlier problem, whose F is F_inliers).
//
// Huber and Cauchy have no graduation: plain iteratively reweighted least squares,
// w_k = ρ′(s_k) until the weights stop changing.
//
// Trusted edges (weight 1 throughout): odometry, |i − j| = 1 in dense indices, or the edges the
// caller marks; priors are never weighted.
//
// The threshold c² on s. Given (GncOptions::threshold > 0) it is used as is. Otherwise it is
// the χ² quantile of the edge's dimension at GncOptions::confidence (Ω taken at its word), and
// with GncOptions::estimate_scale that quantile times the variance factor σ̂² of the problem (the
// a-posteriori variance of unit weight of adjustment theory: σ̂² = Σ_inliers s_k / r, r = residual
// rows − unknowns, the redundancy), so that data whose Ω is off by a constant factor (the shared
// parking-garage's residuals are 10⁴ times below their Ω's prediction, sphere_bignoise's 10² above)
// get the same test as data whose Ω is right. σ̂² is taken first at x⁰ (inflated by the outliers: a
// generous first threshold), then at each GNC result over its inliers, and GNC runs again from the
// last estimate while c² moves by more than GncOptions::scale_tolerance (at most
// GncOptions::max_rounds rounds).
#pragma once

#include <string>
#include <vector>

#include "arbor/core/batch_solver.h"
#include "arbor/core/pose_graph.h"
#include "arbor/core/riemannian_staircase.h"
#include "arbor/core/robust_kernel.h"

namespace arbor {

struct GncOptions {
  /// tls or gm: GNC (Yang et al. Algorithm 1); huber or cauchy: IRLS. Not none.
  KernelKind kernel = KernelKind::kTruncatedLeastSquares;
  /// c² on s = eᵀΩe; ≤ 0: the χ² quantile at `confidence` (× σ̂² with estimate_scale).
  double threshold = 0.0;
  /// With threshold ≤ 0: scale the quantile by the variance factor σ̂² (header comment).
  bool estimate_scale = false;
  /// The χ² confidence of the automatic threshold (c² = χ²_kDoF⁻¹(confidence) σ̂²).
  double confidence = 0.99;
  /// estimate_scale: re-estimate σ̂² over the inliers and run GNC again while c² changes by
  /// more than this fraction, at most max_rounds rounds.
  double scale_tolerance = 0.1;
  int max_rounds = 8;
  /// μ's factor per GNC step (Yang et al.: 1.4).
  double mu_factor = 1.4;
  /// GNC/IRLS steps (each a warm-started LM solve) per round.
  int max_iterations = 200;
  /// Stop when no weight moves by more than this in one step (after binary weights, the other
  /// stop).
  double weight_tolerance = 1e-4;
  /// |i − j| = 1 (dense indices) edges are trusted (weight 1).
  bool trust_odometry = true;
  /// Per-edge marks of trusted edges (the sender's), one per edge, or empty: none beyond
  /// odometry.
  std::vector<char> trusted;
  /// The LM solve of each weighted problem (warm-started, so few iterations each).
  BatchOptions inner = {BatchMethod::kLevenbergMarquardt, 50, 1e-4, false};
  /// The plain least-squares start and the final solve of the inlier problem.
  BatchOptions outer = {BatchMethod::kLevenbergMarquardt, 100, 1e-5, false};
  bool verbose = false;  ///< one line per GNC step on stderr
};

struct GncResult {
  std::vector<double> weights;  ///< per edge, at the last GNC step (trusted: 1)
  std::vector<char> inlier;     ///< per edge: weight > 0.5 (trusted: always)
  std::vector<char> trusted;    ///< per edge: weight held at 1
  int rejected = 0;             ///< edges classified outliers
  int candidates = 0;           ///< edges weighted (not trusted)
  double threshold = 0;         ///< c² used in the last round
  double scale = 1;             ///< σ̂² of the last round (1 when the threshold was given)
  double mu = 0;                ///< μ at the last step
  int rounds = 0;               ///< GNC runs (automatic threshold: one per σ̂²)
  int iterations = 0;           ///< GNC/IRLS steps over all rounds
  int lm_iterations = 0;        ///< LM iterations over all solves
  double F_least_squares = 0;   ///< F at x⁰ (every edge, weight 1)
  double F_all = 0;             ///< Σ eᵀΩe over every edge and prior at the estimate
  double F_inliers = 0;         ///< … over the inlier edges and the priors
  double robust_cost = 0;       ///< Σ ρ(s_k) (the kernel at the last μ) + trusted s_k + priors
  double time_s = 0;
  bool converged = false;  ///< the last round stopped on its weights, not the iteration limit
  std::string message;     ///< why it stopped
};

/// Solves `graph` robustly from *poses (one per pose; the estimate is written there). Throws
/// std::invalid_argument on bad options (kernel none, a bad factor or confidence, a trusted
/// vector of the wrong size) or sizes.
template <class G>
GncResult solveGnc(const PoseGraph<G>& graph, std::vector<G>* poses,
                   const GncOptions& options = {});

/// The certifiable path on GNC's inlier set: SE-Sync's staircase (solveRtr) on the graph without
/// the rejected edges, then every rejected edge whose s = eᵀΩe at that global optimum is within
/// gnc->threshold is taken back and the inlier problem solved again (at most `max_passes`
/// times): LM's answer to the inlier problem can be a local minimum at which true closures look
/// like outliers (MIT with two planted closures: F 128.7 by LM, 35.25 certified). The
/// certificate is that of the final inlier problem (the graph without the edges still
/// rejected), not of the choice of inliers. Updates gnc's classification and F figures; writes
/// the estimate to *poses. Throws what solveRtr throws (priors, a disconnected inlier graph).
struct CertifiedInliers {
  RtrSummary rtr;      ///< the last staircase run
  int readmitted = 0;  ///< rejected edges taken back
  int passes = 0;      ///< staircase runs
};
template <class G>
CertifiedInliers certifyInliers(const PoseGraph<G>& graph, GncResult* gnc, std::vector<G>* poses,
                                const RtrOptions& options = {}, int max_passes = 5);

/// The graph without the edges marked false in `keep` (same poses, ids, priors and fixed).
template <class G>
PoseGraph<G> keepEdges(const PoseGraph<G>& graph, const std::vector<char>& keep);

}  // namespace arbor
