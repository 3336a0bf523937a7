// Robust batch solve of a pose graph with false loop closures: graduated non-convexity (GNC),
// after Yang, Antonante, Tzoumas, Carlone, "Graduated Non-Convexity for Robust Spatial
// Perception", RA-L 2020, Algorithm 1, as GTSAM's GncOptimizer (4.2) runs it, with the kernels
// of core/robust_kernel.h on each edge's s = eᵀΩe. x_init is *poses on entry:
//
//   x⁰ = argmin Σ s_k(x) from x_init          (plain least squares, every weight 1; line 1)
//   μ⁰ = max(1e-6, c² / (2 s_max − c²))       (TLS, Remark 5; GM: 2 s_max / c²), s_max the
//                                              largest s_k of a weighted edge at x_init (GTSAM:
//                                              its initial values, not x⁰), μ⁰ = ∞ for TLS when
//                                              s_max ≤ c²/2: every edge is an inlier already
//   TLS: if every weighted s_k(x⁰) ≤ c², stop at x⁰ (a local minimum of Σ min(s_k, c²): there
//        the cost is least squares, which x⁰ minimises; ours, GTSAM stops only at s_max ≤ c²/2)
//   repeat:  w_k = ρ′_μ(s_k(x))               (eq. 14 for TLS, 12 for GM; trusted edges: 1)
//            x = argmin Σ w_k s_k(x) + priors  (the inner solve, from x_init again: GTSAM
//                                              restarts every inner optimisation from its
//                                              initial values; GncOptions::inner_start)
//            stop if |F_w − F_w,prev| / max(F_w,prev, 1e-7) < cost_tolerance (F_w the weighted
//              objective at the new x, F_w,prev the previous step's, x⁰'s F at the first), or
//              every w_k is within weight_tolerance of 0 or 1 (TLS), or μ = 1 (GM)
//            μ ← μ·1.4 (TLS) or max(1, μ/1.4) (GM)
//   then the inlier set {w_k ≥ RobustKernel::inlierCut: ½ for TLS, the kernel's weight at
//   s = c² for the others, ¼ for GM at μ = 1} is solved once more with weight 1, from the GNC
//   estimate (the inlier problem, whose F is F_inliers; GTSAM returns the last weighted estimate).
//
// Why the restart matters: a warm start carries the basin of x⁰, which every false closure has
// pulled (on intel with 90% false closures x⁰ is far from any good map), and with small μ the
// weighted problem is nearly convex only around the start it is solved from. From x_init (the
// odometry chain, or the file's vertices) each step solves the current weighted problem afresh.
//
// Huber and Cauchy have no graduation: plain iteratively reweighted least squares, w_k = ρ′(s_k),
// warm-started, until the weights stop changing.
//
// Trusted edges (weight 1 throughout; GTSAM's known inliers): odometry, |i − j| = 1 in dense
// indices, or the edges the caller marks; priors are never weighted. Known outliers
// (GncOptions::known_outliers; GTSAM's setKnownOutliers) have weight 0 throughout, x⁰ included,
// and play no part in μ⁰ or the early stop; readmitFitting() may take them back afterwards.
//
// Per-edge kernels (GncOptions::kernels): each weighted edge graduates by its own kind, each
// kind with its own μ (μ⁰ from the largest residual of its edges, its own schedule); GNC stops
// when every kind is at its kernel at once (TLS weights binary, GM at μ = 1, Huber and Cauchy
// weights still) or on the cost. The early stop at x⁰ is TLS's and needs every weighted edge TLS.
//
// The threshold c² on s. Given (GncOptions::threshold > 0) it is used as is (GTSAM's barcSq = 1
// on its error ½‖r‖² is c² = 2). Otherwise it is the χ² quantile of the edge's dimension at
// GncOptions::confidence, Ω taken at its word (GTSAM's default,
// setInlierCostThresholdsAtProbability (0.99)), and with GncOptions::estimate_scale that quantile
// times the variance factor σ̂² of the problem (σ̂² = Σ_inliers s_k / r, r = residual rows −
// unknowns, the redundancy), taken first at x⁰, then at each GNC result over its inliers, GNC
// running again from x_init while c² moves by more than GncOptions::scale_tolerance (at most
// GncOptions::max_rounds rounds). That estimate feeds on its own truncation (TLS drops the largest
// true residuals, σ̂² shrinks, the next c² drops more): docs/benchmarks.md, "Robust batch (GNC)",
// measures it; it is not the default.
#pragma once

#include <string>
#include <vector>

#include "arbor_slam/core/batch_solver.h"
#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/core/riemannian_staircase.h"
#include "arbor_slam/core/robust_kernel.h"

namespace arbor {

/// Where each inner (weighted) solve of a GNC step starts.
enum class GncInnerStart {
  kInitial,   ///< from x_init, the poses given to solveGnc (GTSAM's GncOptimizer)
  kPrevious,  ///< from the previous step's estimate (warm start; cheaper, keeps x⁰'s basin)
};

/// At which estimate the residuals that set μ⁰ are taken.
enum class GncMuStart {
  kInitial,       ///< x_init (GTSAM's GncOptimizer::initializeMu)
  kLeastSquares,  ///< x⁰, the least-squares solution over every edge
};

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
  /// μ's factor per GNC step (Yang et al., GTSAM's muStep: 1.4).
  double mu_factor = 1.4;
  /// μ⁰'s floor for TLS (GTSAM: 1e-6; a huge s_max would give μ⁰ ≈ 0).
  double min_initial_mu = 1e-6;
  /// GNC/IRLS steps per round (GTSAM's maxIterations: 100).
  int max_iterations = 100;
  /// TLS stops when every weight is within this of 0 or 1 (GTSAM's weightsTol); IRLS stops when
  /// no weight moves by more than this in one step.
  double weight_tolerance = 1e-4;
  /// Stop when the weighted objective changes by less than this fraction between two steps
  /// (GTSAM's relativeCostTol).
  double cost_tolerance = 1e-5;
  GncInnerStart inner_start = GncInnerStart::kInitial;
  GncMuStart mu_start = GncMuStart::kInitial;
  /// |i − j| = 1 (dense indices) edges are trusted (weight 1).
  bool trust_odometry = true;
  /// Per-edge marks of trusted edges (the sender's), one per edge, or empty: none beyond
  /// odometry.
  std::vector<char> trusted;
  /// Per-edge marks of known outliers (weight 0 throughout: GTSAM's knownOutliers), one per
  /// edge, or empty: none. An edge cannot be both trusted and a known outlier.
  std::vector<char> known_outliers;
  /// Per-edge kernel kinds, one per edge, or empty: `kernel` for every edge. KernelKind::kNone
  /// in it: `kernel` for that edge. Ignored on trusted edges.
  std::vector<KernelKind> kernels;
  /// The solve of each weighted problem (GTSAM: Gauss–Newton, relative tolerance 1e-5, at most
  /// 100 iterations).
  BatchOptions inner = batchOptions(BatchMethod::kGaussNewton, 100, 1e-5);
  /// The plain least-squares start and the final solve of the inlier problem.
  BatchOptions outer = batchOptions(BatchMethod::kLevenbergMarquardt, 100, 1e-5);
  bool verbose = false;  ///< one line per GNC step on stderr
  /// Checked before each GNC step and, through inner and outer (whose own tokens are replaced
  /// by this one), inside every solve. A cancelled solve keeps the estimate of the last step
  /// that finished (x⁰'s partial solve when cancelled in it), skips the inlier problem and sets
  /// GncResult::cancelled.
  CancellationToken cancel = {};
};

struct GncResult {
  std::vector<double> weights;  ///< per edge, at the last GNC step (trusted: 1)
  std::vector<char> inlier;     ///< per edge: weight ≥ its kernel's inlierCut (trusted: always)
  std::vector<char> trusted;    ///< per edge: weight held at 1
  int rejected = 0;             ///< edges classified outliers
  int candidates = 0;           ///< edges weighted (not trusted)
  double threshold = 0;         ///< c² used in the last round
  double scale = 1;             ///< σ̂² of the last round (1 when the threshold was given)
  double mu = 0;                ///< μ at the last step
  int rounds = 0;               ///< GNC runs (automatic threshold: one per σ̂²)
  int iterations = 0;           ///< GNC/IRLS steps over all rounds
  int lm_iterations = 0;        ///< solver iterations over all solves (inner and outer)
  double F_least_squares = 0;   ///< F at x⁰ (every edge, weight 1)
  double F_all = 0;             ///< Σ eᵀΩe over every edge and prior at the estimate
  double F_inliers = 0;         ///< … over the inlier edges and the priors
  double robust_cost = 0;       ///< Σ ρ(s_k) (the kernel at the last μ) + trusted s_k + priors
  double time_s = 0;
  bool converged = false;  ///< the last round stopped on its weights or cost, not the step limit
  bool cancelled = false;  ///< stopped by GncOptions::cancel
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
/// `take_back` (> 0; 0: gnc->threshold) is taken back and the inlier problem solved again (at
/// most `max_passes` times): LM's answer to the inlier problem can be a local minimum at which true
/// closures look like outliers (MIT with two planted closures: F 128.7 by LM, 35.25 certified). The
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
                                const RtrOptions& options = {}, int max_passes = 5,
                                double take_back = 0);

/// Takes back the rejected edges that fit: every edge gnc classified an outlier (known outliers
/// included, trusted ones never rejected) whose s = eᵀΩe at *poses is within `threshold` becomes
/// an inlier, and the inlier problem is solved again by `options` from *poses, until no edge is
/// taken back (at most `max_passes` solves). The online smoother's hysteresis in a batch: `arbor
/// batch --init online` starts GNC with the replay's rejected closures as known outliers, so GNC's
/// graduation cannot let them back in, and takes back here those that the refined estimate fits
/// at the replay's own c² (its entry test). Updates gnc's classification, weights and F figures;
/// returns the number taken back.
template <class G>
int readmitFitting(const PoseGraph<G>& graph, GncResult* gnc, std::vector<G>* poses,
                   double threshold, const BatchOptions& options, int max_passes = 5);

/// Whether solveGnc holds edge k at weight 1: odometry (|i − j| = 1 in dense indices) with
/// options.trust_odometry, or marked in options.trusted.
template <class G>
bool trustedEdge(const PoseGraph<G>& graph, const GncOptions& options, int k);

/// The graph without the edges marked false in `keep` (same poses, ids, priors and fixed).
template <class G>
PoseGraph<G> keepEdges(const PoseGraph<G>& graph, const std::vector<char>& keep);

}  // namespace arbor
