// The online robust layer's options, its rules and its constants (bayestree/online_gnc.h).
//
// Twelve options (RobustOptions) and eight rules (RobustRule, plus the two the options
// `scale` and `corroboration_window` switch). Every other number the layer uses is a constant
// below, each with the reason for its value. docs/design.md, "Online robust smoothing", has
// the tables.
#pragma once

#include <string>
#include <vector>

#include "arbor_slam/core/robust_kernel.h"

namespace arbor {

/// How a new loop closure is first judged (online_gnc.h, "first check").
enum class EntryTest {
  kInnovation,  ///< m = rᵀ(I + AΣAᵀ)⁻¹r, Σ from the Bayes tree
  kResidual,    ///< m = s₀ = rᵀr (Σ taken as 0)
};
/// The scale of Ω the threshold is put on.
enum class NoiseScale {
  kEstimated,  ///< σ̂² from the closures' innovations (bayestree/noise_scale.h)
  kGiven,      ///< Ω at its word: σ̂² = 1
};
const char* toString(EntryTest entry);   ///< "innovation", "residual"
const char* toString(NoiseScale scale);  ///< "estimated", "given"

/// The rules that RobustOptions::rules_off can switch off, each by the property it guarantees
/// (online_gnc.h's header comment has each one's mechanism).
enum class RobustRule {
  /// warm-up: no closure is judged on a noise scale that has not been estimated yet; closures
  /// that arrive before σ̂² are held at weight 0 and judged once it is there.
  kWarmUp,
  /// rehold: when the first σ̂² raises c² at least kReholdGrowth times, no closure stays
  /// rejected by the c² that Ω's word gave before it; those are judged again.
  kRehold,
  /// scale start: a re-estimate of σ̂² never starts above the last one, so false groups that
  /// come to outnumber true runs cannot move σ̂² by their median alone.
  kScaleStart,
  /// final confirm: no inlier that no other inlier agrees with ends the replay with its
  /// leave-one-out innovation (L) past kFinalConfirmMargin·c².
  kFinalConfirm,
  /// end scale: the end judges by the scale of the whole graph's (L) where that is at least
  /// kEndScaleGap times tighter than the scale read from innovations at arrival.
  kEndScale,
  /// end word: no loop closure ends rejected whose residual at the final estimate is within
  /// its own noise model's χ² bound.
  kEndWord,
};
const char* toString(RobustRule rule);  ///< "warm-up", "rehold", …, "end-word"
/// Every rule, in declaration order.
const std::vector<RobustRule>& robustRules();

/// A set of RobustRule (RobustOptions::rules_off). A value type.
class RuleSet {
 public:
  RuleSet() = default;
  RuleSet(std::initializer_list<RobustRule> rules);
  bool has(RobustRule rule) const { return (bits_ & bit(rule)) != 0; }
  RuleSet& add(RobustRule rule);
  bool empty() const { return bits_ == 0; }
  bool operator==(const RuleSet& other) const { return bits_ == other.bits_; }
  bool operator!=(const RuleSet& other) const { return bits_ != other.bits_; }
  /// The names, comma-separated ("" when empty).
  std::string toString() const;

 private:
  static unsigned bit(RobustRule rule) { return 1u << static_cast<unsigned>(rule); }
  unsigned bits_ = 0;
};

/// The inverses of the toString()s: the value named `text`, else std::invalid_argument
/// "must be a or b, not 'text'" (the caller puts its flag's or field's name before it).
EntryTest parseEntryTest(const std::string& text);
NoiseScale parseNoiseScale(const std::string& text);
RobustRule parseRobustRule(const std::string& text);
/// Comma-separated rule names ("" or "none": the empty set).
RuleSet parseRuleSet(const std::string& text);

struct RobustOptions {
  /// The kernel the closures graduate towards: tls (default) or gm graduate (GNC); huber and
  /// cauchy are reweighted without graduation (IRLS). Not none.
  KernelKind kernel = KernelKind::kTruncatedLeastSquares;
  /// c² on s = eᵀΩe; ≤ 0: the χ² quantile of the edge's dimension (kDoF) at `confidence`, Ω
  /// taken at its word (as `arbor batch --robust --inlier-threshold chi2`).
  double threshold = 0.0;
  double confidence = 0.99;  ///< of the automatic threshold and σ̂²'s quantiles, in (0, 1)
  /// The scale of Ω the threshold is put on: σ̂² estimated from the closures (default), or Ω
  /// at its word.
  NoiseScale scale = NoiseScale::kEstimated;
  /// Poses K between the ends of two closures that may corroborate each other (online_gnc.h,
  /// "corroboration"): σ̂² is estimated from corroborated closures' innovations; 0: from every
  /// closure's innovation (≥ 0).
  int corroboration_window = 10;
  /// The first check of a new closure: its innovation (default) or its residual s₀.
  EntryTest entry = EntryTest::kInnovation;
  double mu_step = 1.4;  ///< μ's factor per graduation step (Yang et al.: 1.4), > 1
  /// Graduation steps per OnlineSmoother::update, ≥ 1: the first rides on the update, each
  /// further one runs one more smoother update (only while closures graduate).
  int steps_per_update = 1;
  /// A closure still graduating after this many steps is settled with the kernel's own weight.
  int max_steps_per_closure = 40;
  /// Settled closures re-checked at the kernel per update (round robin); 0: only in finalize().
  int rechecks_per_update = 16;
  /// Rounds of finalize(): graduate to the end, re-check every closure, relinearise all; again
  /// while a re-check changed a weight (≥ 1).
  int finalize_rounds = 10;
  /// The rules switched off (none by default): to see what one does, never to tune a file.
  RuleSet rules_off;

  bool on(RobustRule rule) const { return !rules_off.has(rule); }
  /// Why the options cannot be used ("" when they can): names the field and the value.
  std::string problem() const;
};

// The constants. Each is stated by what it guarantees, where a derivation gives one, or by the
// data it was chosen on (tuning seeds 1–3 of `arbor bench robust --family`, and the shared
// robust files); docs/benchmarks.md has the held-out seeds 4–10.
namespace robust_constants {

/// TLS: the surrogate counts as the kernel once μ reaches this (riSAM's TLS convergence).
inline constexpr double kMaxMu = 1e5;
/// Huber, Cauchy (IRLS): settled when a step moves the weight by less than this.
inline constexpr double kWeightTolerance = 1e-3;
/// A settled inlier graduates again when its s passes kRecheckMargin·c², and a closure whose
/// first check passes kEntryBand·c² enters at weight 0 instead of graduating. With c² the χ²_d
/// quantile at 0.99, a true closure passes 2c² with probability 4·10⁻⁵ (d = 3) or 8·10⁻⁶
/// (d = 6): a true closure in the χ² tail does not flap.
inline constexpr double kRecheckMargin = 2.0;
inline constexpr double kEntryBand = 2.0;
/// Innovations before σ̂² is first estimated: the median of 20 χ²_3 samples is within about
/// ±30% of its value (one standard error), enough to place c² within the band above.
inline constexpr int kScaleMinSamples = 20;
/// Rule kRehold: a first σ̂² at least 4 times Ω's word means the closures judged before it
/// were judged at a quarter of their scale or less, where a true χ²_3 passes c² with
/// probability ≥ 0.4; below that, closures already judged stand.
inline constexpr double kReholdGrowth = 4.0;
/// Rule kFinalConfirm: (L) past 1.25·c² drops an unbacked inlier. A true closure's m₋ is
/// σ²χ²_d: past 1.25 times the 0.99 quantile with probability 0.003 (d = 3), 0.002 (d = 6).
/// Chosen on the tuning data between the largest unbacked true m₋ (1.17·c²) and the false
/// ones graduation keeps (≥ 1.28·c²).
inline constexpr double kFinalConfirmMargin = 1.25;
/// ... and 1 over the end's own c² (kEndScale), read from (L) at the whole graph's estimate,
/// which needs no room for the estimate's error at arrival.
inline constexpr double kEndConfirmMargin = 1.0;
/// Rule kEndScale: (L) of at most this many settled inliers and as many trusted edges, evenly
/// spaced: the 0.99 quantile is then read from about five samples past it.
inline constexpr int kEndScaleSamples = 512;
/// ... replaces c² only when at least this many times smaller: the tail of a few hundred
/// samples moves by tens of percent between runs, a factor 2 by far more than that.
inline constexpr double kEndScaleGap = 2.0;
/// ... read during the replay too, once the poses have grown by this factor since the last
/// reading and the updates have re-eliminated kEndScaleWork times the tree's factorisation
/// flops (a reading costs about two): the readings cost at most 1/8 of the updates' work.
inline constexpr double kEndScaleGrowth = 1.05;
inline constexpr double kEndScaleWork = 16.0;

}  // namespace robust_constants
}  // namespace arbor
