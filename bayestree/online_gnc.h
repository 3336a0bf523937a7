// Online robust smoothing in the Bayes tree: graduated non-convexity per loop closure, in the
// manner of riSAM (McGann, Rogers, Kaess, "Robust Incremental Smoothing and Mapping", ICRA 2023),
// over IncrementalSmoother's weight seam (setFactorWeight). The online layer (OnlineSmoother)
// owns one OnlineGnc and calls it around each smoother update; nothing here changes the Bayes
// tree except through setFactorWeight, so every weight change is a relinearisation of that one
// factor and only its keys' cliques (with their ancestors) are re-eliminated. A closure at
// weight 0 (rejected, or entering rejected) is out of the elimination altogether: no fill, no
// clique holds it; taken back it enters as a new factor (a fold-in of its two keys).
//
// Which edges are weighted. Odometry (consecutive ids, |from − to| = 1), edges the caller marks
// trusted, an edge that creates one of its poses (its only constraint: e = 0 by construction)
// and an edge that joins two components (the smaller moves rigidly onto it, e = 0 again; with
// nothing else between the two it cannot be judged) keep weight 1 for good and are reported
// "trusted". Priors are never weighted. Every other edge is a loop closure and is judged.
//
// One closure's life (the kernel ρ_μ on s = eᵀΩe, core/robust_kernel.h; c² the threshold):
//   first check   the innovation m at the estimate before the closure enters (what the graph
//                 without it says; RobustOptions::entry). With r the closure's whitened residual
//                 there, A its whitened Jacobian on its two poses and Σ their joint covariance
//                 in the Bayes tree,
//                   m = rᵀ (I + A Σ Aᵀ)⁻¹ r                                             (E)
//                 is what adding it at weight 1 raises the linearised objective by (the least
//                 squares update's own cost); TLS gives it weight 1 iff that is below the c²
//                 weight 0 costs. So m ≤ c²: weight 1, settled inlier, no graduation — on clean
//                 data where every closure passes, the factors and hence the estimate are the
//                 plain smoother's, bit for bit (w = 1 changes nothing in
//                 Factor::linearizeWeighted). TLS, GM with m > entry_band·c²: weight 0, settled
//                 outlier (it pulls nothing, so its cliques are not re-eliminated again). A · Σ ·
//                 Aᵀ is one forward substitution along the two poses' paths to the root
//                 (IncrementalSmoother::predictionCovariance). EntryTest::kResidual judges s₀
//                 instead (m = s₀: Σ = 0), and so does a closure to a pose not in the tree yet.
//   entry         m in (c², entry_band·c²] (any m > c² for Huber, Cauchy): the closure enters
//                 with the convex surrogate: μ₀ = initialMu(s₀)
//                 (TLS: c²/(2s₀ − c²); GM: 2s₀/c²) and w₀ = ρ′_μ₀(s₀), as GNC starts from the
//                 largest residual (Yang et al., RA-L 2020, Alg. 1) — here the closure's own.
//
// The threshold on an estimated noise scale (RobustOptions::scale). Files' Ω are often wrong by
// a constant factor; with the model right, the innovations of the true closures are χ²_d
// (d = kDoF), with Ω too confident by a factor σ², σ²χ²_d. NoiseScale::kEstimated estimates σ̂²
// from the innovations of every judged closure so far (estimateNoiseScale: a median, truncated
// at tail_factor·c² to leave the false closures out and corrected for that truncation, then the
// same from the `confidence` quantile for heavy tails, within max_tail_scale of the median's,
// once tail_min_samples are kept) once scale_min_samples of them are in; before that, and with
// NoiseScale::kGiven, σ̂² = 1 and c² is the given one. After it the threshold in use is the
// estimator's own truncation, tail_factor · c² · σ̂²: what it counts as a false closure is what is
// rejected (on correctly modelled data σ̂² ≈ 1; on the shared 2D files about 0.02, on the garage
// 2·10⁻⁴, Ω being too weak there). With fewer than 3 innovations within the truncation, or a σ̂²
// above 1 that fewer than a quarter of them support at Ω's word while there are fewer than
// loosen_min_samples, there is no estimate and Ω is taken at its word (the given c², not
// tail_factor times it).
//   corroboration with RobustOptions::corroboration_window K > 0 (default 10; 0: off), σ̂² is
//                 estimated from the innovations of corroborated closures: two closures a→b
//                 (z₁, Ω₁) and c→d (z₂, Ω₂) with |a − c| ≤ K and |b − d| ≤ K (or reversed)
//                 corroborate each other when the estimate's short chains x_a⁻¹x_c and
//                 x_d⁻¹x_b carry z₂ onto a second measurement of a→b that agrees with z₁:
//                   ẑ = (x_a⁻¹ x_c) z₂ (x_d⁻¹ x_b),  e = e(z₁⁻¹ ẑ),  eᵀ(Ω₁⁻¹ + Ω₂⁻¹)⁻¹e ≤ c²    (P)
//                 (c² the given one times the pairs' own scale: estimateNoiseScale of every
//                 neighbouring pair's s so far, from their median, true pairs being most of
//                 them over a run, and past 1 only under its loosening rule; Ω₂ taken in b's
//                 frame, the two ends being at most K poses apart).
//                 σ̂²'s fixed points then start from the corroborated innovations' untruncated
//                 median, not from 1: on sphere_bignoise (Ω ~200× too confident) no true
//                 closure is within the truncation at σ² = 1. True closures come in runs along a
//                 revisit and agree with their neighbours; a false one agrees with nothing (random,
//                 local) or only with its own group. Where the first closures are mostly false
//                 (intel with 90%: the first 21 are), their innovations on the odometry chain are
//                 1.7–2800 at Ω's word while the true ones', later, are 0.002: a median of
//                 them took σ̂² to 66 and accepted them all. Until scale_min_samples closures are
//                 corroborated the warm-up goes on; with loosen_min_samples judged and still
//                 too few corroborated (isolated closures) σ̂² is estimated from every
//                 innovation, as with K = 0.
//   the start     (RobustOptions::scale_start) each later estimate from the corroborated
//                 innovations starts at their untruncated median or at the last σ̂², whichever
//                 is lower: false groups agree with each other (P) and may come to outnumber the
//                 true runs in the corroborated set, and a fixed point started at their median
//                 stays among them (a generated Manhattan world, 1000 poses, 50% group false
//                 closures, seed 3: σ̂² 1.25 → 2683 at the 200th, every closure accepted). From
//                 the last σ̂² the fixed point reads what lies within the truncation there: it
//                 still grows step by step, and comes down from a false start as before. The
//                 first estimate, and the first after one is lost, start from the median.
//   warm-up       a closure that arrives before the first estimate cannot be judged on the scale
//                 yet: RobustOptions::warm_up kHold (default) keeps it at weight 0 (out of the
//                 tree, its innovation recorded) and judges it by its innovation as on entry
//                 once the estimate is there (or in finalize()); kGiven judges it at once, Ω at
//                 its word. On the garage, whose Ω is ~10⁴ too weak, the 4th closure is false
//                 and passes Ω's χ² test; accepted, it wrecks the Gauss–Newton smoother.
//                 The update that lets the held closures in relinearises everything once
//                 (OnlineSmoother::update): on 3D laps with Ω nine times too confident, the one
//                 Gauss–Newton step from the odometry chain left the next closures'
//                 innovations 20–65 times χ²'s median and σ̂² at 18.9 for 9.
//                 The warm-up ends when σ̂² has a source, estimated or not: where the loosening
//                 rule refuses an estimate, closures are judged at Ω's word until one comes, and
//                 the round robin of re-checks takes them back one at a time, on an estimate
//                 that has none of them, once it does. A generated sphere (10 rings of 30,
//                 rotation noise 0.1 rad with Ω 100 times too confident, 10% random false
//                 closures, seed 1) had every closure rejected at Ω's word until the 486th
//                 update, then σ̂² 206 (c² × 618), and the re-checks let 23 in, false ones among
//                 them: F 10¹² two updates later. With rehold_growth X (4 by default) a first
//                 estimate that raises c² at least X times holds those closures again, and the
//                 next update judges them as the warm-up's end does: that sphere (seeds 1–3) ends
//                 at F* with exactly the false closures rejected, and so does intel with 90%
//                 group false closures (seed 1), which diverges without it. On the other robust
//                 files and the clean ones it changes no rejected set (sphere_bignoise, where it
//                 fires, ends at the plain replay's F instead of 12.5% below it).
//   a shrinking c²  when an estimate of σ̂² takes c² below 1/recheck_margin of the c² every
//                 settled inlier was last checked against (raised with c² as it grows; not when
//                 the estimate is lost and Ω's word stands in), the next step checks them all
//                 at once, not in the round robin's turn: each whose s is past
//                 recheck_margin·c² graduates again from μ₀ at s (sweepInliers; residuals only,
//                 no Σ). Where the first closures are mostly false, the first σ̂² lets groups of
//                 them in; when the true closures take σ̂² down (intel, 90% group false closures:
//                 c² 1933 → 0.62), the round robin graduated one false closure of 30, the
//                 estimate moved, and its next turn found 16 true closures bent past 2c² (s 3–47)
//                 with 29 false ones still at weight 1; it graduated the true ones down and the
//                 replay diverged. Checked together, 17 false ones (s 1.3–240) graduate at once
//                 and leave within the update; the rest follow in the round robin.
//   graduation    before each of the following smoother updates: s at the current estimate,
//                 μ ← μ·step (TLS) or μ/step (GM), w = ρ′_μ(s), setFactorWeight(w). At most
//                 RobustOptions::steps_per_update steps per OnlineSmoother::update (the first
//                 rides on the update itself, the others each run one more smoother update),
//                 so no update hangs, however many closures graduate.
//   settled       TLS: w binary (s outside the band [μ/(μ+1) c², (μ+1)/μ c²], where the kernel
//                 and its surrogate agree) or μ ≥ RobustOptions::max_mu; GM: μ at 1; Huber,
//                 Cauchy (no graduation, IRLS): w moved by less than weight_tolerance. Or after
//                 max_steps_per_closure steps, with the kernel's own weight at s.
//   confirmed     (RobustOptions::confirm, off by default) TLS with EntryTest::kInnovation and
//                 an estimated σ̂²: graduation compares s, the residual at an estimate the
//                 closure itself pulls towards, with c². Where little else sees its poses a
//                 false closure can pull them to within c² and settle at weight 1 (smallGrid3D
//                 with 90% local false closures, seed 1: (1, 27) at s 61.6 against c² 192.8).
//                 With `confirm`, a closure graduation settles at 1 is judged once more, at the
//                 step after the update that eliminated it so, by what keeping it costs the
//                 whole linearised objective against the c² that dropping it costs (TLS's own
//                 choice for one closure, the others held): its leave-one-out innovation, from
//                 its whitened residual r at the estimate with it and Σ with it,
//                   m₋ = rᵀ (I − A Σ Aᵀ)⁻¹ r      (L, bayestree/closure_innovation.h)
//                 ((E) of the graph without it; (1, 27): 423). m₋ > c²: weight 0, settled
//                 outlier — unless a settled inlier agrees with it (P). Why it is off: the
//                 first true closures of sphere_bignoise with 10% random false closures,
//                 (0, 50) and (2, 51), reach m₋ 6.1·10⁴ and 2.6·10⁴ against c² 3831 (Ω ~200×
//                 too confident, a ring of odometry between them) before any inlier can agree
//                 with them; dropped, the replay loses the ring and diverges. On the garage and
//                 intel true closures sit up to 1.6 times c² by (L), and intel's isolated
//                 (99, 1371) and (346, 1375) at 1.13 and 1.16 times where smallGrid3D's false
//                 (58, 100) is at 1.41: no bound on (L) alone keeps the true and drops the
//                 false; with the agreeing runs exempt, the end's margin does (below).
//   confirmed at the end (RobustOptions::final_confirm_margin, 1.25 by default; 0: off) the
//                 same judgement in finalize(), for every settled TLS inlier no inlier agrees
//                 with, each round, at the estimate of the whole replay: m₋ > margin·c² drops it,
//                 at most one closure per pose a round, the largest m₋ first (the other is judged
//                 again next round, at the estimate without the first).
//                 A partner recorded on arrival agreed through the estimate of that moment,
//                 which false closures may have bent; with end_partners_agree (default) it backs
//                 the closure only while the two still agree (P) at the end's estimate
//                 (sphere_bignoise with 10% random false closures: 619 → 627 of 645 rejected,
//                 1.034 → 1.015 F*; no other shared or generated robust file changes), read in
//                 both closures' frames (pairSBothWays) and within the c² in use, not the
//                 pairs' scale (smallGrid3D with 50% local false closures, seed 2: the false
//                 (1, 33) was backed by the true (11, 38) at 62.5 in its own frame, 1005 in the
//                 other's, and ended at 1.145 F*; now 1.018).
//                 By then sphere_bignoise's closures agree with their runs (none of its
//                 inliers is unbacked above 0.4·c²), and the margin sits between the largest
//                 unbacked true closure's m₋ measured on the shared and generated robust files
//                 (intel's (346, 1375), 1.16–1.17·c²; smallGrid3D's (7, 2) 1.13) and the false
//                 ones graduation keeps (smallGrid3D's (58, 100) 1.28–1.80, (1, 27) 4.2; torus3D's
//                 (163, 188) 4.3), chosen on the seed-1 files and checked on seeds 2 and 3.
//                 Agreement (P) backs a closure only between closures whose ends are more
//                 than 2K poses apart: a shorter closure's neighbour can lie on the chain
//                 between its own ends, and (P) then reads it against the estimate, which the
//                 group it belongs to has bent (smallGrid3D's false (29, 35), 6 poses long,
//                 "agreed" with the true (20, 29)). A false closure a long true run agrees with
//                 is not reached, and agreement cannot be ignored: true closures in runs sit up
//                 to 2.7·c² by (L).
//   the end's scale (RobustOptions::end_scale_samples, 512 by default; 0: off) c² in use comes
//                 from innovations at arrival, which carry the estimate's error of that moment
//                 and, where false closures got in, their bending. At the end each of finalize()'s
//                 (L) passes re-estimates it from (L) at the estimate of the whole graph: σ²_med of
//                 the settled inliers' m₋ (a minority of false ones sits in its tail), times the
//                 tail's reach past the median in the trusted edges' m₋ (σ̂²/σ²_med of
//                 estimateNoiseScale; no false edge among them, but their own noise: on intel
//                 the closures are 1.6 times noisier than the odometry, so their scale is not
//                 taken), each from at most end_scale_samples evenly spaced, and c²_end =
//                 tail_factor·c²·σ̂²_end. It replaces c² for the pass's drops and for taking
//                 closures back only when at least end_scale_gap (2) times smaller: the tail of
//                 a few hundred samples moves by tens of percent. sphere_bignoise with 10%
//                 random false closures: c² 22386 from the innovations, c²_end 6700 in the
//                 first pass and about 5000 later, where its true closures' m₋ reach 4760; on
//                 the other shared robust files c²_end is within 0.6–1.3 of c². Where it
//                 replaces c², the pass drops past end_confirm_margin·c²_end (1), not
//                 final_confirm_margin·c² (1.25): read at the whole graph's estimate, it needs
//                 less room than c² from arrivals (that sphere_bignoise file: 1.0113 → 1.0090
//                 F*, 631 → 635 rejected, no true one; smallGrid3D with 10% local false
//                 closures, seed 3: 1.676 → 1, the false (4, 23) dropped and the true (4, 45)
//                 taken back; no other robust or clean file changes).
//   the end's scale on the way (RobustOptions::end_scale_growth, 1.05, and end_scale_work, 16;
//                 growth 0: off) the same reading after an update, once the poses have grown
//                 by that factor and the updates re-eliminated that many times the tree's
//                 factorisation flops since the last one: where c²_end is at least
//                 end_scale_gap below c², the settled inliers no inlier agrees with are
//                 dropped past final_confirm_margin·c²_end, as finalize()'s pass drops them,
//                 and a closure so dropped is taken back only within c²_end. Once a reading
//                 has dropped closures, the end's scale stands in finalize() wherever it is
//                 below c² (the drops change σ̂²'s samples, and c² could end within the gap).
//                 On sphere_bignoise with 10% random false closures the false closures come
//                 out during the replay, where each held the tops it touched open until
//                 finalize(): updates 128 → 28 s, p99 246 → 43 ms, 1.0139 → 1.0113 F*.
//   kept at Ω's word (RobustOptions::end_word, on by default) finalize()'s last stage, after
//                 its rounds: every rejected TLS or GM closure whose residual s = eᵀΩe at the
//                 final estimate is within the given c² (Ω at its word: the χ² quantile, or
//                 RobustOptions::threshold) is taken back at weight 1; the estimate is
//                 relinearised with them, and again while one came back (at most
//                 finalize_rounds). Property: no loop closure ends rejected that the final
//                 estimate explains within its own noise model's χ² bound, the poses taken as
//                 exact. Why it is needed: σ̂² is a median's scale, and where Ω is cautious (σ̂²
//                 ≪ 1) the c² in use is tail_factor·c²·σ̂², far below Ω's bound; true closures
//                 with a heavy tail (a car's few closures, each with much of its loop's share)
//                 sit past it and stay out (the small-loop family, Ω 20–100 times cautious,
//                 seeds 1–3: 3–4 true closures of each world rejected, F 1.10–1.20 F*; their
//                 s at the end 0.2–0.6 of Ω's c²). Why s and not (E): m = s/(1 + AΣAᵀ) in one
//                 dimension, and a long false closure's AΣAᵀ is large: on M3500 with 50% random
//                 false closures the false ones' m at the end reach down to 0.27 of Ω's c², their
//                 s at least 55 times it; the true ones' s stay below 0.02 of it. Why only back,
//                 not out: dropping inliers by s, an estimate they pull, adds nothing to (L) on the
//                 shared and generated files (the same cases solved), and is not needed for
//                 the property.
//   status        inlier iff w ≥ the kernel's weight at s = c² (RobustKernel::inlierCut), so
//                 at the kernel iff s ≤ c²: for TLS w ≥ ½ (GNC's convention, as GTSAM's
//                 GncOptimizer and the reference figures count), for GM at μ = 1 w ≥ ¼.
//
// Which closures are re-weighted on an update. riSAM resets μ of every graduated factor in the
// "update-involved" top of the tree whenever new graduated factors arrive and iterates to
// convergence within the update (RISAM2::relinearizeFactor, iterateToConvergence), which is
// what makes it slow on large graphs (shared/reference/robust-anchors.tsv: M3500 186 s).
// Here the closures graduating now are stepped, and the settled ones are re-checked at the
// kernel in a bounded round robin (RobustOptions::rechecks_per_update per update, all of them
// in finalize()): a settled outlier at weight 0 whose innovation (E) is within the c² in use,
// re-judged once c² has grown by a tenth since its last judgement and in finalize() (with the
// residual test, on every re-check: whose s is within recheck_margin·c²) is taken back (weight 1),
// a settled inlier whose residual grew beyond recheck_margin·c² graduates again from μ₀ at that
// residual. These are the "affected" closures of riSAM, found by looking rather
// than through the tree; the margin keeps a true closure in the χ² tail from flapping.
//
// Excluding a closure (exclude/include, by smoother factor index): the GNC stops weighting it
// and leaves its weight to the caller (a front end that takes an edge back sets it to 0);
// include() re-admits it through the first check and sets its weight itself.
//
// Reseeding (OnlineSmoother::reseed) keeps every weight (they live on the factors, which the
// rebuild re-adds) and this state; remap() finds the factors' new indices.
#pragma once

#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "arbor_slam/bayestree/incremental_smoother.h"
#include "arbor_slam/bayestree/noise_scale.h"
#include "arbor_slam/bayestree/robust_options.h"
#include "arbor_slam/core/edge_trust.h"
#include "arbor_slam/core/factor.h"
#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/core/robust_kernel.h"

namespace arbor {

/// The estimator's options at the online layer's confidence (bayestree/noise_scale.h).
NoiseScaleOptions scaleOptions(const RobustOptions& o);
/// bayestree/noise_scale.h's estimator at the online layer's options.
inline NoiseScaleEstimate estimateNoiseScale(std::vector<double> m, int dof, double c2,
                                             const RobustOptions& o, bool from_median = false) {
  return estimateNoiseScale(std::move(m), dof, c2, scaleOptions(o), from_median);
}

/// What one OnlineGnc::step re-checks among the settled closures.
enum class StepScope {
  kRoundRobin,  ///< RobustOptions::rechecks_per_update of them (an ordinary update)
  kAll,         ///< every one (the update after a reseed)
  kFinalize,    ///< every one, and (L) at final_confirm_margin (a round of finalize())
};

enum class ClosureStatus {
  kInlier,    ///< weight ≥ its kernel's inlierCut (TLS ½, GM ¼)
  kOutlier,   ///< below it: rejected
  kTrusted,   ///< never weighted (marked, or it created a pose or joined two components)
  kExcluded,  ///< taken out of the GNC by the caller (exclude()); its weight is the caller's
};

const char* toString(ClosureStatus status);  ///< "inlier", "outlier", "trusted", "excluded"

/// One loop closure as the GNC sees it now.
struct ClosureReport {
  Key from = 0, to = 0;
  double weight = 1.0;    ///< the factor's inlier weight in the smoother
  double residual = 0.0;  ///< s = eᵀΩe at its last check
  ClosureStatus status = ClosureStatus::kInlier;
  /// still being graduated, or held in the warm-up (status by its current weight)
  bool graduating = false;
  int steps = 0;    ///< graduation steps it has taken
  int factor = -1;  ///< its index in the smoother (−1 until the update that adds it)
  KernelKind kernel = KernelKind::kTruncatedLeastSquares;  ///< the kernel it is judged by
};

struct ClosureCounts {
  int inlier = 0, outlier = 0, trusted = 0, excluded = 0;
  int graduating = 0;        ///< of inlier + outlier, those not settled yet
  int graduation_steps = 0;  ///< weight changes made by graduation, in total
  int rechecks = 0;          ///< settled closures re-checked, in total
  /// of the rechecks of rejected closures, those (E)'s lower bound kept out without a path solve
  int rechecks_bounded = 0;
  int regraduated = 0;  ///< re-checks that changed a settled closure's weight
  int unconfirmed = 0;  ///< inliers set to weight 0 by (L), online or in finalize()
  /// rejected closures taken back at the end by their residual within Ω's χ² bound
  /// (RobustOptions::end_word)
  int kept_at_word = 0;
};

template <class G>
class OnlineGnc {
 public:
  using Edge = RelativePoseEdge<G>;

  /// Throws std::invalid_argument with RobustOptions::problem() on bad options.
  explicit OnlineGnc(const RobustOptions& options);

  /// The first check of a new edge (dense indices) before it enters the smoother: returns the
  /// inlier weight it enters with (1, or w₀ for a closure that graduates) and records it when
  /// it is a loop closure. `structural`: the edge created one of its poses or joined two
  /// components (trusted). `kernel`: the kernel this closure graduates towards (kNone:
  /// RobustOptions::kernel). Odometry is not judged unless `trust` is kRobust.
  double admit(const IncrementalSmoother<G>& smoother, Key from, Key to, EdgeTrust trust,
               bool structural, const Edge& edge, KernelKind kernel = KernelKind::kNone);
  /// Before a smoother update: one graduation step of every graduating closure and the round
  /// robin of re-checks (StepScope). Returns the weights changed.
  int step(IncrementalSmoother<G>& smoother, StepScope scope = StepScope::kRoundRobin);
  /// After a smoother update, during the replay: the end's scale read again once the poses
  /// have grown by end_scale_growth since the last reading (header comment, "the end's scale
  /// on the way"); where it is at least end_scale_gap times below the c² in use, the settled
  /// inliers no inlier agrees with are dropped past final_confirm_margin times it. Returns the
  /// weights changed (the next smoother update takes them in).
  int readEndScaleOnTheWay(IncrementalSmoother<G>& smoother, double update_flops);
  /// Before the rounds of a finalize(): within them a closure is taken back from weight 0 at
  /// most kEndTakeBacks times, so one that (E) takes back at weight 0 and (L) drops at weight
  /// 1, round after round (each reads it at the estimate the other's round left, and they
  /// differ where the problem is not linear), settles out instead of flipping until
  /// finalize_rounds.
  void beginFinalize() {
    for (Closure& c : closures_) c.end_take_backs = 0;
  }
  /// After a smoother update: the indices of the closures it added.
  void resolve(const IncrementalSmoother<G>& smoother);
  /// After the smoother was rebuilt with the same factors in another order (reseed).
  void remap(const IncrementalSmoother<G>& smoother);

  /// Takes factor `factor` out of the GNC (its weight is the caller's from now on), or puts it
  /// back through the first check (include sets its weight). No-ops for a factor the GNC does
  /// not weight (odometry, trusted, priors). Throws std::invalid_argument on an index out of
  /// range.
  void exclude(IncrementalSmoother<G>& smoother, int factor);
  void include(IncrementalSmoother<G>& smoother, int factor);

  /// Whether the GNC judges factor `factor` (a loop closure graduating or settled; not trusted,
  /// excluded, odometry or a prior).
  bool judges(int factor) const;
  /// Whether the GNC holds factor `factor` as a settled inlier now: a closure it judges, not
  /// graduating, not held in the warm-up, its weight at least its kernel's inlierCut.
  bool settledInlier(int factor) const;
  /// The kernel factor `factor` is judged by (its closure's own, per edge) when the GNC judges
  /// it, else KernelKind::kNone.
  KernelKind kernelOf(int factor) const;
  /// ρ of factor `factor` at s = eᵀΩe: its closure's kernel at μ = 1 when the GNC judges it
  /// (TLS: min(s, c²)), else s. Σ of it over the factors is the robust cost Σρ.
  double rho(int factor, double s) const;

  bool graduating() const { return !graduating_.empty(); }
  /// Closures held in the warm-up (RobustRule::kWarmUp), not judged yet.
  size_t held() const { return held_.size(); }
  /// Every settled inlier whose residual is past recheck_margin·c² graduates again from μ₀ at
  /// it, all in this step (header comment, "a shrinking c²"); returns the weights set.
  int sweepInliers(IncrementalSmoother<G>& smoother);
  /// Every rejected TLS or GM closure whose residual s at the smoother's estimate is within the
  /// given c² (Ω at its word) back at weight 1 (header comment, "kept at Ω's word"; finalize()'s
  /// last stage, with RobustOptions::end_word); returns how many.
  int takeBackAtWord(IncrementalSmoother<G>& smoother);
  /// A re-checked closure's new state taken in (step's round robin, sweepInliers): listed as
  /// graduating, or its weight set in the smoother; returns the weights set (0 or 1).
  int takeRecheck(IncrementalSmoother<G>& smoother, int id);
  /// The first `at_most` held closures, in arrival order, judged by their innovations against
  /// the c² in use (those not in the smoother yet stay held); returns the weights set.
  int judgeHeld(IncrementalSmoother<G>& smoother,
                size_t at_most = std::numeric_limits<size_t>::max());
  ClosureCounts counts() const;
  std::vector<ClosureReport> closures() const;
  /// c² in use: the given c² (warm-up, NoiseScale::kGiven), then tail_factor · c² · σ̂².
  double threshold() const { return c2_; }
  /// The c² finalize()'s last (L) pass judged by (header comment, "the end's scale"; 0 before
  /// one).
  double thresholdAtEnd() const { return c2_end_; }
  /// σ̂² (1 until scale_min_samples innovations, without an estimate, and with
  /// NoiseScale::kGiven).
  double noiseScale() const { return scale_; }
  /// The last estimate (estimateNoiseScale; `estimated` false before the first).
  const NoiseScaleEstimate& noiseEstimate() const { return estimate_; }
  /// The innovations the last σ̂² was estimated from (0 before the first estimate).
  int noiseSamples() const { return samples_used_; }
  const RobustOptions& options() const { return options_; }

 private:
  enum class State { kGraduating, kSettled, kTrusted, kExcluded };
  using Paths = typename IncrementalSmoother<G>::PredictionPaths;
  struct Closure {
    Key from = 0, to = 0;
    int i = 0, j = 0;  ///< dense indices
    G z;               ///< the measurement (to find the factor after an update)
    int factor = -1;
    State state = State::kSettled;
    KernelKind kernel = KernelKind::kTruncatedLeastSquares;  ///< its own (per edge)
    double mu = 0, weight = 1, s = 0;
    double judged_c2 = 0;  ///< c² in use when it was last judged by its innovation
    int steps = 0;
    bool held = false;  ///< at weight 0 until σ̂² is estimated (RobustRule::kWarmUp)
    bool dropped_on_the_way = false;  ///< by readEndScaleOnTheWay: taken back by the end's c²
    int end_take_backs = 0;     ///< from weight 0 in this finalize() (beginFinalize resets it)
    double m = 0;               ///< its innovation on entry
    bool corroborated = false;  ///< another closure agrees with it (P)
    std::vector<int> partners;  ///< agreeing closures (P) by id, both spansLoop (recordsPartners)
    typename Edge::Matrix covariance = Edge::Matrix::Identity();  ///< Ω⁻¹ of its measurement
  };

  RobustKernel kernelAt(const Closure& c, double mu) const;
  /// TLS, GM: kernels whose settled weight is (near) binary, so a closure may enter at 0.
  bool binaryKernel(const Closure& c) const;
  /// The closure's kernel's own weight at s (TLS: 1 or 0; GM at μ = 1; Huber, Cauchy: ρ′(s)).
  double finalWeight(const Closure& c, double s) const;
  /// Its status: weight ≥ its kernel's RobustKernel::inlierCut (TLS ½, GM ¼, Cauchy ½, Huber 1).
  bool isInlier(const Closure& c) const;
  /// The first check at s with innovation m (m = s: the residual test): settles at weight 1,
  /// at weight 0 (m > entry_band·c², TLS and GM, with `may_reject`) or starts graduation from
  /// μ₀(s).
  void enter(Closure* c, double s, double m, bool may_reject);
  /// (E) for the edge at the smoother's estimate; s when Σ is not there (EntryTest::kResidual,
  /// a pose not in the tree yet).
  /// `paths`: kKept when many closures are judged on one tree (finalize(), a re-check of all).
  double innovation(const IncrementalSmoother<G>& smoother, const Edge& edge, double s,
                    Paths paths = Paths::kOnce) const;
  /// ≤ innovation(): from (E)'s lower bound (closure_innovation.h), the poses' marginals as
  /// kKept reads them; 0 where Σ is not there.
  double innovationLowerBound(const IncrementalSmoother<G>& smoother, const Edge& edge,
                              double s) const;
  /// Whether a closure that agreed with c (P) is a settled inlier now; with `now`, one that
  /// still agrees with it at that smoother's estimate.
  bool backed(const Closure& c, const IncrementalSmoother<G>* now = nullptr) const;
  /// Whether at least `needed` of c's partners are settled inliers and, with `now`, agree with
  /// it (P) at that smoother's estimate within `pair_bound` (backed).
  bool agreedBy(const Closure& c, const IncrementalSmoother<G>* now, double pair_bound,
                int needed) const;
  /// (P)'s s of closures a and b at the smoother's estimate (+∞ when their ends are not within
  /// corroboration_window of each other's).
  double pairS(const IncrementalSmoother<G>& smoother, const Closure& a, const Closure& b) const;
  /// pairS with a's ends at xa, xb (the smoother's estimate of them, read once by observe()
  /// for all of a's neighbours).
  double pairS(const IncrementalSmoother<G>& smoother, const Closure& a, const Closure& b,
               const G& xa, const G& xb) const;
  /// The larger of pairS(a, b) and pairS(b, a): (P) read in both closures' frames.
  double pairSBothWays(const IncrementalSmoother<G>& smoother, const Closure& a,
                       const Closure& b) const;
  /// Whether c's ends are more than 2·corroboration_window poses apart (a partner's must be).
  bool spansLoop(const Closure& c) const;
  /// (L) for a settled TLS closure the tree holds at weight 1 and no inlier agrees with, when
  /// it exceeds `bound` (nullopt otherwise, and for every other closure). `at_the_end`
  /// (finalize()): kept path solves, and a partner backs it only while
  /// it still agrees (P) at the estimate.
  std::optional<double> unconfirmedBy(const IncrementalSmoother<G>& smoother, Closure* c,
                                      double bound, bool at_the_end);
  /// unconfirmedBy, and then dropUnconfirmed; returns whether it dropped c.
  bool unconfirmed(IncrementalSmoother<G>& smoother, Closure* c, double bound,
                   bool at_the_end = false);
  /// A closure (L) judged past its bound: weight 0, counted in ClosureCounts::unconfirmed.
  void dropUnconfirmed(IncrementalSmoother<G>& smoother, Closure* c);
  /// The c² finalize() judges by: the end's where there is one, else the c² in use.
  double endBound() const;
  /// finalize()'s c² (header comment, "the end's scale"): at most the c² in use.
  double endThreshold(const IncrementalSmoother<G>& smoother) const;
  /// finalize()'s (L) over every settled inlier at final_confirm_margin·c²_end (endThreshold),
  /// the largest m₋ first and at most one drop per pose in a round: (L) reads one closure with
  /// the others held, so of two past the bound that share a pose the second is judged again
  /// next round, at the estimate without the first. Marks the closures it drops in `dropped`
  /// (by id), which the same step's re-checks leave alone (the tree still holds them at 1 until
  /// the next update). Returns the weights changed.
  int confirmAll(IncrementalSmoother<G>& smoother, std::vector<char>* dropped);
  /// Drops the closures `over` names ((m₋, id), each past its bound), the largest m₋ first and
  /// at most one per pose: (L) reads one closure with the others held, so of two that share a
  /// pose the second is judged again at the estimate without the first. Returns the ids dropped.
  std::vector<int> dropLargestPerPose(IncrementalSmoother<G>& smoother,
                                      std::vector<std::pair<double, int>> over);
  /// Whether (L) judges c: a settled TLS closure the tree holds at weight 1.
  bool judgedByL(const IncrementalSmoother<G>& smoother, const Closure& c) const;
  /// c's (L) m₋ when past `bound` (c judgedByL), else nullopt; `at_the_end`: kept path solves.
  std::optional<double> innovationPast(const IncrementalSmoother<G>& smoother, const Closure& c,
                                       double bound, bool at_the_end) const;
  /// Before many (L) on one tree: the joints of every factor the tree holds, from one walk
  /// (IncrementalSmoother::keepSharedCliqueJoints).
  void keepHeldJoints(const IncrementalSmoother<G>& smoother) const;
  /// Records closure `id`'s innovation m, looks for closures that corroborate it (P), and
  /// re-estimates σ̂² and c² (NoiseScale::kEstimated).
  void observe(const IncrementalSmoother<G>& smoother, int id, double m);
  /// Whether closures a and b agree through the estimate between their ends (P); false when
  /// their ends are not within corroboration_window of each other's. A neighbouring pair's s
  /// joins pair_s_ (the pairs' scale), so each pair is to be tested once.
  bool agree(const IncrementalSmoother<G>& smoother, const Closure& a, const Closure& b,
             const G& xa, const G& xb);
  /// The innovations σ̂² is estimated from now (nullptr: none yet).
  const std::vector<double>* scaleSource() const;
  /// σ̂² estimated, or given (NoiseScale::kGiven): new closures are judged at once.
  bool scaleKnown() const;
  /// Whether (L) judges every inlier in finalize() (RobustOptions::final_confirm_margin).
  bool confirmsAtTheEnd() const;
  /// Whether (P)'s partners are recorded (read by backed()).
  bool recordsPartners() const;
  /// One graduation step at s; returns the new weight.
  double graduate(Closure* c, double s);
  double residual(const IncrementalSmoother<G>& smoother, const Closure& c) const;
  void setWeight(IncrementalSmoother<G>& smoother, Closure* c, double w);
  /// Finds factor indices for the closures not resolved among factors [first, numFactors).
  void match(const IncrementalSmoother<G>& smoother, int first, std::vector<int>* ids);
  int closureOf(int factor) const;

  RobustOptions options_;
  double c2_given_ = 0;  ///< RobustOptions::threshold or the χ² quantile
  double c2_ = 0;
  double c2_end_ = 0;               ///< endThreshold at its last reading (0: none yet)
  int next_reading_ = 0;            ///< poses at which readEndScaleOnTheWay reads it next
  double flops_since_reading_ = 0;  ///< the updates' re-elimination flops since the last one
  /// A reading on the way dropped closures: the end's scale then stands wherever it is below
  /// the c² in use, not only end_scale_gap below it.
  bool dropped_on_the_way_ = false;
  NoiseScaleEstimate estimate_;
  double scale_ = 1.0;
  std::vector<double> innovations_;                   ///< of every judged closure
  std::vector<double> corroborated_;                  ///< of the corroborated ones
  const std::vector<double>* last_source_ = nullptr;  ///< what the last σ̂² came from
  size_t next_estimate_ = 0;  ///< the source's size at which σ̂² is estimated next
  int samples_used_ = 0;
  std::multimap<Key, int> by_low_end_;  ///< judged closures by min(from, to)
  /// (P)'s s of every neighbouring pair so far: [0, pair_s_sorted_) sorted at the last estimate
  /// of their scale, the rest in arrival order.
  std::vector<double> pair_s_;
  size_t pair_s_sorted_ = 0;
  NoiseScaleOptions scale_options_;  ///< options_'s estimator constants (scaleOptions)
  NoiseScaleCuts cuts_;              ///< estimateNoiseScale's χ² points at kDoF and c2_given_
  double pair_scale_ = 1.0;          ///< their σ̂² (1 before 10 of them)
  size_t next_pair_estimate_ = 0;    ///< pair_s_.size() at which it is estimated next
  std::vector<Closure> closures_;
  std::vector<int> unresolved_;  ///< closures added since the last resolve()
  std::vector<int> graduating_;  ///< closures graduating, by id
  std::vector<int> held_;        ///< closures held in the warm-up, by id
  std::vector<int> by_factor_;   ///< factor index → closure id (−1: none)
  size_t cursor_ = 0;            ///< round robin of re-checks over closures_
  /// The c² every settled inlier was last checked against at once (sweepInliers), raised with
  /// c² as it grows; c² below it by recheck_margin sets sweep_due_.
  double c2_swept_ = 0;
  bool sweep_due_ = false;
  int resolved_factors_ = 0;  ///< factors seen by resolve()
  ClosureCounts totals_;      ///< graduation_steps, rechecks, regraduated
};

extern template class OnlineGnc<SE2>;
extern template class OnlineGnc<SE3>;

}  // namespace arbor
