// Online robust smoothing in the Bayes tree: graduated non-convexity per loop closure, in the
// manner of riSAM (McGann, Rogers, Kaess, "Robust Incremental Smoothing and Mapping", ICRA 2023),
// with the surrogate kernels of GNC (Yang, Antonante, Tzoumas, Carlone, RA-L 2020), over
// IncrementalSmoother's weight seam (setFactorWeight). OnlineSmoother owns one OnlineGnc and calls
// it around each smoother update; a weight change is a relinearisation of that one factor, so only
// its keys' cliques and their ancestors are re-eliminated. A closure at weight 0 is out of the
// elimination (no clique holds it); taken back, it enters as a new factor would.
//
// Which edges are weighted. Odometry (|from − to| = 1), edges the caller marks trusted, an edge
// that creates one of its poses and an edge that joins two components keep weight 1 ("trusted");
// priors are never weighted; every other edge is a loop closure and is judged.
//
// The tests (bayestree/closure_innovation.h). With r a closure's whitened residual, A its whitened
// Jacobian on its two poses and Σ their joint covariance in the Bayes tree:
//   m  = rᵀ (I + A Σ Aᵀ)⁻¹ r   (E)  innovation, at the estimate without the closure: what adding
//                                   it at weight 1 raises the linearised objective by;
//   m₋ = rᵀ (I − A Σ Aᵀ)⁻¹ r   (L)  leave-one-out: (E) of the graph without it, read with it;
//   (P) two closures with ends within K poses agree when the estimate's short chains carry one
//       onto a second measurement of the other within c² times the pairs' own scale.
// TLS keeps a closure exactly when its cost at weight 1 is below the c² that weight 0 costs.
//
// One closure's life (the kernel ρ_μ on s = eᵀΩe, core/robust_kernel.h; c² the threshold in use):
//   first check   (E) before it enters (RobustOptions::entry; kResidual: s₀, Σ taken as 0).
//                 m ≤ c²: weight 1, settled inlier (clean data is the plain smoother bit for
//                 bit); m > kEntryBand·c²: weight 0, settled outlier.
//   entry         otherwise the convex surrogate: μ₀ = initialMu(s₀), w₀ = ρ′_μ₀(s₀), as GNC
//                 starts from the largest residual.
//   graduation    before each later update: s at the current estimate, μ one step on (mu_step),
//                 w = ρ′_μ(s); at most steps_per_update steps an update, so no update hangs.
//   settled       when the surrogate's weight is the kernel's, or after max_steps_per_closure.
//   status        inlier iff w ≥ the kernel's weight at s = c² (RobustKernel::inlierCut).
//
// The rules, each by the property it guarantees (RobustRule; docs/design.md has the table):
//   the noise scale  the threshold is put on σ̂², the factor by which Ω is wrong, estimated from
//                 the closures' innovations (bayestree/noise_scale.h); the c² in use is the
//                 estimator's truncation, tail_factor·c²·σ̂². Without an estimate, Ω's word.
//   corroboration σ̂² is read from closures another closure agrees with (P): false closures
//                 agree with nothing, or only with their own group.
//   the start     a re-estimate of σ̂² starts at most at the last one: false groups that come
//                 to outnumber the true runs cannot move σ̂² by their median.
//   warm-up       no closure is judged on a scale not estimated yet: early closures are held at
//                 weight 0 and judged once σ̂² is there (the update that lets them in
//                 relinearises everything once).
//   rehold        a first σ̂² that raises c² kReholdGrowth times holds the closures rejected at
//                 Ω's word before it again, to be judged as at the warm-up's end.
//   a shrinking c²  when σ̂² takes c² below 1/kRecheckMargin of the c² the inliers were last
//                 checked against, every inlier is re-checked at once (sweepInliers).
//   confirmed at the end  in finalize(), an inlier no partner backs is dropped when its (L) is
//                 past kFinalConfirmMargin·c², one per pose a round, the largest first. A
//                 partner spans more than 2K poses, as the closure it backs does, and still
//                 agrees (P) at the end, read in both frames.
//   the end's scale  finalize() re-reads the scale from (L) at the whole graph's estimate
//                 (endThreshold) and judges by it where it is kEndScaleGap times tighter.
//   the end's scale on the way  the same reading after updates, at growing intervals bounded in
//                 work (kEndScaleGrowth, kEndScaleWork), so false closures leave before the end.
//   kept at Ω's word  finalize()'s last stage: a rejected closure whose s at the final estimate
//                 is within Ω's own χ² bound comes back (a heavy tail of true closures that a
//                 median's scale puts past c²).
//
// Which closures are re-weighted on an update. riSAM resets μ of every graduated factor in the
// update-involved top of the tree and iterates to convergence, which is its cost on large graphs.
// Here the graduating closures take one step each, and the settled ones are re-checked in a
// bounded round robin (rechecks_per_update; all of them in finalize()): an outlier whose (E) is
// within the c² in use comes back, an inlier whose s passes kRecheckMargin·c² graduates again.
// These are riSAM's "affected" closures, found by their residuals rather than through the tree;
// the margin keeps a true closure in the χ² tail from flapping.
//
// Excluding a closure (exclude/include): the GNC leaves its weight to the caller; include()
// re-admits it through the first check. Reseeding keeps every weight (they live on the factors);
// remap() finds the factors' new indices.
//
// The class is defined in three files: online_gnc.cc (a closure's life: admit, graduation,
// re-checks, the warm-up), online_gnc_scale.cc (the noise scale and (P)) and online_gnc_end.cc
// (the end pass: (L), the end's scale, kept at Ω's word). Options, rules and constants:
// bayestree/robust_options.h. Measurements, the end pass and where the layer still fails:
// docs/design.md, "Online robust smoothing".
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
  kFinalize,    ///< every one, and (L) at kFinalConfirmMargin (a round of finalize())
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
  /// (RobustRule::kEndWord)
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
  /// have grown by kEndScaleGrowth since the last reading (header comment, "the end's scale
  /// on the way"); where it is at least end_scale_gap times below the c² in use, the settled
  /// inliers no inlier agrees with are dropped past kFinalConfirmMargin times it. Returns the
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
  /// Every settled inlier whose residual is past kRecheckMargin·c² graduates again from μ₀ at
  /// it, all in this step (header comment, "a shrinking c²"); returns the weights set.
  int sweepInliers(IncrementalSmoother<G>& smoother);
  /// Every rejected TLS or GM closure whose residual s at the smoother's estimate is within the
  /// given c² (Ω at its word) back at weight 1 (header comment, "kept at Ω's word"; finalize()'s
  /// last stage, with RobustRule::kEndWord); returns how many.
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
  /// σ̂² (1 until kScaleMinSamples innovations, without an estimate, and with
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
  /// at weight 0 (m > kEntryBand·c², TLS and GM, with `may_reject`) or starts graduation from
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
  /// still agrees with it at that smoother's estimate, within the pairs' bound and the c² in use.
  bool backed(const Closure& c, const IncrementalSmoother<G>* now = nullptr) const;
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
  /// finalize()'s (L) over every settled inlier at kFinalConfirmMargin·c²_end (endThreshold),
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
  /// Whether (L) judges every inlier in finalize() (RobustRule::kFinalConfirm).
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
  /// c² as it grows; c² below it by kRecheckMargin sets sweep_due_.
  double c2_swept_ = 0;
  bool sweep_due_ = false;
  int resolved_factors_ = 0;  ///< factors seen by resolve()
  ClosureCounts totals_;      ///< graduation_steps, rechecks, regraduated
};

extern template class OnlineGnc<SE2>;
extern template class OnlineGnc<SE3>;

}  // namespace arbor
