#include "arbor_slam/bayestree/online_gnc.h"

#include <algorithm>
#include <cmath>
#include <initializer_list>
#include <limits>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>

#include <boost/math/distributions/chi_squared.hpp>

#include "arbor_slam/bayestree/closure_innovation.h"

namespace arbor {
namespace {

bool samePose(const SE2& a, const SE2& b) {
  return a.x() == b.x() && a.y() == b.y() && a.cos() == b.cos() && a.sin() == b.sin();
}
bool samePose(const SE3& a, const SE3& b) {
  return a.translation() == b.translation() && a.quaternion().coeffs() == b.quaternion().coeffs();
}

bool odometry(Key from, Key to) { return from - to == 1 || to - from == 1; }

// Take-backs of one closure from weight 0 in one finalize() (OnlineGnc::beginFinalize). Two: a
// closure that (L) drops twice may still settle in after its second take-back as the others'
// drops move the estimate (intel with 90% random false closures, seed 2: one true closure; at
// one take-back it stays out and F is 6% higher); past that it flips until finalize_rounds.
constexpr int kEndTakeBacks = 2;

// The sample count at which an estimate re-made from n samples is made next: every new one up
// to 64, then when their number has grown by an eighth (O(k) each, O(k) in all).
size_t nextEstimateAt(size_t n) { return n < 64 ? n + 1 : n + n / 8; }

}  // namespace

NoiseScaleOptions scaleOptions(const RobustOptions& o) {
  NoiseScaleOptions s;
  s.confidence = o.confidence;
  return s;
}

const char* toString(ClosureStatus status) {
  switch (status) {
    case ClosureStatus::kInlier:
      return "inlier";
    case ClosureStatus::kOutlier:
      return "outlier";
    case ClosureStatus::kTrusted:
      return "trusted";
    case ClosureStatus::kExcluded:
      return "excluded";
  }
  return "unknown";
}

template <class G>
OnlineGnc<G>::OnlineGnc(const RobustOptions& options) : options_(options) {
  const std::string problem = options_.problem();
  if (!problem.empty()) throw std::invalid_argument(problem);
  c2_given_ = options_.threshold > 0 ? options_.threshold
                                     : chiSquareThreshold(options_.confidence, G::kDoF);
  c2_ = c2_given_;
  scale_options_ = scaleOptions(options_);
  cuts_ = NoiseScaleCuts(G::kDoF, c2_given_, scale_options_);
}

// σ̂² from the innovations so far (scaleSource), once scale_min_samples of them are in;
// re-estimated at nextEstimateAt's counts.
template <class G>
void OnlineGnc<G>::observe(const IncrementalSmoother<G>& smoother, int id, double m) {
  if (options_.scale != NoiseScale::kEstimated || !std::isfinite(m)) return;
  Closure& c = closures_[static_cast<size_t>(id)];
  c.m = m;
  innovations_.push_back(m);
  if (const Key K = options_.corroboration_window; K > 0) {
    // (P) against the judged closures whose low end is within K of this one's: ends paired
    // within K (either way round) put the low ends within K of each other.
    const Key low = std::min(c.from, c.to);
    const G xa = smoother.estimate(c.i), xb = smoother.estimate(c.j);
    for (auto it = by_low_end_.lower_bound(low - K); it != by_low_end_.end(); ++it) {
      if (it->first > low + K) break;
      Closure& other = closures_[static_cast<size_t>(it->second)];
      if (other.state == State::kExcluded || !agree(smoother, c, other, xa, xb)) continue;
      if (!other.corroborated) {
        other.corroborated = true;
        corroborated_.push_back(other.m);
      }
      c.corroborated = true;
      // Partners (read only by (L)'s backed()) span more than 2K poses each: the ends of a
      // shorter closure's neighbour can lie on the chain between its own ends, and (P) then
      // reads it against the estimate's chain (bent to it once it is in), not against the
      // neighbour's measurement (header comment, "confirmed at the end").
      if (recordsPartners() && spansLoop(c) && spansLoop(other)) {
        c.partners.push_back(it->second);
        other.partners.push_back(id);
      }
    }
    if (c.corroborated) corroborated_.push_back(m);
    by_low_end_.emplace(low, id);
  }
  const std::vector<double>* source = scaleSource();
  if (!source) return;
  const size_t n = source->size();
  if (source == last_source_ && n < next_estimate_) return;
  last_source_ = source;
  samples_used_ = static_cast<int>(n);
  const bool had_estimate = estimate_.estimated;
  // The fixed point starts from the untruncated median, and with RobustRule::kScaleStart at
  // most from the last σ̂² (header comment, "the noise scale").
  const double start_cap = had_estimate && options_.on(RobustRule::kScaleStart)
                               ? scale_
                               : std::numeric_limits<double>::infinity();
  estimate_ = estimateNoiseScale(*source, cuts_, scale_options_,
                                 /*from_median=*/source == &corroborated_, start_cap);
  scale_ = estimate_.sigma2;
  // The estimator's own truncation; Ω at its word without an estimate.
  const double c2_before = c2_;
  c2_ = estimate_.estimated ? scale_options_.tail_factor * c2_given_ * scale_ : c2_given_;
  // The first estimate, many times Ω's word: what was rejected at Ω's word is held again, to be
  // judged as the warm-up's closures are (RobustRule::kRehold; header, "warm-up").
  const double growth = options_.on(RobustRule::kRehold) ? robust_constants::kReholdGrowth : 0.0;
  if (growth > 0 && !had_estimate && estimate_.estimated && c2_ >= growth * c2_before &&
      options_.on(RobustRule::kWarmUp)) {
    for (size_t k = 0; k < closures_.size(); ++k) {
      Closure& o = closures_[k];
      if (o.state != State::kSettled || o.weight != 0.0 || o.held || !binaryKernel(o) ||
          growth * o.judged_c2 > c2_)
        continue;
      o.held = true;
      held_.push_back(static_cast<int>(k));
    }
  }
  // An estimate taking c² below 1/recheck_margin of what every inlier was last checked against:
  // the next step checks them all at once (header comment, "a shrinking c²"). Not on losing the
  // estimate: Ω's word then stands in for want of one and says nothing of the inliers.
  if (c2_ > c2_swept_) c2_swept_ = c2_;
  if (estimate_.estimated && robust_constants::kRecheckMargin * c2_ < c2_swept_) {
    sweep_due_ = true;
    c2_swept_ = c2_;
  }
  next_estimate_ = nextEstimateAt(n);
}

template <class G>
const std::vector<double>* OnlineGnc<G>::scaleSource() const {
  const size_t enough = static_cast<size_t>(robust_constants::kScaleMinSamples);
  if (options_.corroboration_window == 0)
    return innovations_.size() >= enough ? &innovations_ : nullptr;
  if (corroborated_.size() >= enough) return &corroborated_;
  if (innovations_.size() >=
      std::max(enough, static_cast<size_t>(scale_options_.loosen_min_samples)))
    return &innovations_;
  return nullptr;
}

// (P)'s s: closure b turned into a second measurement of a's a→b through the estimate's chains
// between their ends, against a's own (+∞ when their ends are not within K of each other's).
template <class G>
double OnlineGnc<G>::pairS(const IncrementalSmoother<G>& smoother, const Closure& a,
                           const Closure& b) const {
  return pairS(smoother, a, b, smoother.estimate(a.i), smoother.estimate(a.j));
}

template <class G>
double OnlineGnc<G>::pairS(const IncrementalSmoother<G>& smoother, const Closure& a,
                           const Closure& b, const G& xa, const G& xb) const {
  const Key K = options_.corroboration_window;
  auto near = [K](Key x, Key y) { return x - y <= K && y - x <= K; };
  G z2 = b.z;
  int c = b.i, d = b.j;
  if (!(near(a.from, b.from) && near(a.to, b.to))) {
    if (!(near(a.from, b.to) && near(a.to, b.from))) return std::numeric_limits<double>::infinity();
    z2 = z2.inverse();  // b reversed: d→c read as c→d (Ω₂ kept, the ends being close)
    std::swap(c, d);
  }
  const G z_hat = xa.inverse()
                      .compose(smoother.estimate(c))
                      .compose(z2)
                      .compose(smoother.estimate(d).inverse())
                      .compose(xb);
  const typename Edge::Vector e = relativePoseError(a.z, G::Identity(), z_hat);
  const typename Edge::Matrix cov = a.covariance + b.covariance;
  const double s = e.dot(cov.ldlt().solve(e));
  return std::isfinite(s) ? s : std::numeric_limits<double>::infinity();
}

// (P)'s s read in both closures' frames: the larger. The chains between the ends carry the
// rotation error of each reading to the other's translation by their lever arm, so one frame
// alone can let a pair agree that the other frame refuses (smallGrid3D, 50% local false
// closures, seed 2: the false (1, 33) read against the true (11, 38) is 62.5 in its own frame
// and 1005 in (11, 38)'s).
template <class G>
double OnlineGnc<G>::pairSBothWays(const IncrementalSmoother<G>& smoother, const Closure& a,
                                   const Closure& b) const {
  return std::max(pairS(smoother, a, b), pairS(smoother, b, a));
}

// (P): b agrees with a.
template <class G>
bool OnlineGnc<G>::agree(const IncrementalSmoother<G>& smoother, const Closure& a, const Closure& b,
                         const G& xa, const G& xb) {
  const double s = pairS(smoother, a, b, xa, xb);
  if (!std::isfinite(s)) return false;
  // On the pairs' own scale: estimateNoiseScale of every neighbouring pair's s so far, from
  // their untruncated median (true pairs, which come in runs, are most of them over a run),
  // once there are 10. Past 1 only under the estimator's loosening rule: where the first pairs
  // are all false (intel with 90% local false closures: the first ~150), their median would
  // let them all agree.
  pair_s_.push_back(s);
  if (pair_s_.size() >= 10 && pair_s_.size() >= next_pair_estimate_) {
    // Sorted up to pair_s_sorted_: the new ones sorted and merged in (the estimate reads only
    // the sorted values, not their order of arrival).
    const auto sorted_end = pair_s_.begin() + static_cast<std::ptrdiff_t>(pair_s_sorted_);
    std::sort(sorted_end, pair_s_.end());
    std::inplace_merge(pair_s_.begin(), sorted_end, pair_s_.end());
    pair_s_sorted_ = pair_s_.size();
    pair_scale_ =
        estimateNoiseScaleSorted(pair_s_, cuts_, scale_options_, /*from_median=*/true).sigma2;
    next_pair_estimate_ = nextEstimateAt(pair_s_.size());
  }
  return s <= c2_given_ * pair_scale_;
}

template <class G>
bool OnlineGnc<G>::scaleKnown() const {
  return options_.scale != NoiseScale::kEstimated || last_source_ != nullptr;
}

// (E): m = rᵀ(I + A Σ Aᵀ)⁻¹r, r the whitened residual at the estimate, A the whitened Jacobian
// at the linearisation point (the tangent Σ is of), Σ the poses' joint covariance in the tree.
template <class G>
double OnlineGnc<G>::innovation(const IncrementalSmoother<G>& smoother, const Edge& edge, double s,
                                Paths paths) const {
  if (options_.entry == EntryTest::kResidual) return s;
  const std::optional<double> m = closureInnovation(smoother, edge, paths);
  return m ? std::min(*m, s) : s;  // no Σ (a pose not through an update yet): s
}

// min(m_lb, s) ≤ min(m, s) = innovation(): past a bound, innovation() is past it too.
template <class G>
double OnlineGnc<G>::innovationLowerBound(const IncrementalSmoother<G>& smoother, const Edge& edge,
                                          double s) const {
  if (options_.entry == EntryTest::kResidual) return s;
  const std::optional<double> m = closureInnovationLowerBound(smoother, edge);
  return m ? std::min(*m, s) : 0.0;  // no Σ: nothing known from below
}

template <class G>
bool OnlineGnc<G>::confirmsAtTheEnd() const {
  // Without corroboration (K = 0) no closure is backed, and true closures in runs sit up to
  // 2.7·c² by (L): the garage lost three more at K = 0 (F_clean 1.0092 → 1.0184).
  return options_.on(RobustRule::kFinalConfirm) && options_.corroboration_window > 0 &&
         options_.entry == EntryTest::kInnovation && estimate_.estimated;
}

template <class G>
bool OnlineGnc<G>::recordsPartners() const {
  return options_.on(RobustRule::kFinalConfirm);
}

template <class G>
bool OnlineGnc<G>::spansLoop(const Closure& c) const {
  const Key span = c.from > c.to ? c.from - c.to : c.to - c.from;
  return span > 2 * options_.corroboration_window;
}

template <class G>
bool OnlineGnc<G>::backed(const Closure& c, const IncrementalSmoother<G>* now) const {
  // At an estimate (finalize()), never above the closures' own c²: where false pairs are many
  // the pairs' scale runs far past it (smallGrid3D with 90% false closures: c²·σ̂²_pairs 5571
  // against c² 52 for groups, seed 1; 4480 against 79 for local ones, seed 2).
  const double pair_bound =
      now == nullptr ? c2_given_ * pair_scale_ : std::min(c2_given_ * pair_scale_, c2_);
  return std::any_of(c.partners.begin(), c.partners.end(), [&](int id) {
    const Closure& p = closures_[static_cast<size_t>(id)];
    return p.state == State::kSettled && !p.held && isInlier(p) &&
           (now == nullptr || pairSBothWays(*now, c, p) <= pair_bound);
  });
}

template <class G>
bool OnlineGnc<G>::judgedByL(const IncrementalSmoother<G>& smoother, const Closure& c) const {
  return c.state == State::kSettled && c.weight == 1.0 && !c.held && c.factor >= 0 &&
         c.factor < smoother.numFactors() && c.kernel == KernelKind::kTruncatedLeastSquares;
}

template <class G>
std::optional<double> OnlineGnc<G>::innovationPast(const IncrementalSmoother<G>& smoother,
                                                   const Closure& c, double bound,
                                                   bool at_the_end) const {
  const Edge& edge = *smoother.factors()[static_cast<size_t>(c.factor)].relativePose();
  // In the tree at weight 1 (judgedByL): (L); without Σ it is kept.
  const std::optional<double> m =
      leaveOneOutInnovation(smoother, edge, at_the_end ? Paths::kKept : Paths::kOnce);
  if (!m || *m <= bound) return std::nullopt;
  return m;
}

template <class G>
std::optional<double> OnlineGnc<G>::unconfirmedBy(const IncrementalSmoother<G>& smoother,
                                                  Closure* c, double bound, bool at_the_end) {
  if (!judgedByL(smoother, *c) || backed(*c, at_the_end ? &smoother : nullptr)) return std::nullopt;
  c->judged_c2 = c2_;
  return innovationPast(smoother, *c, bound, at_the_end);
}

template <class G>
bool OnlineGnc<G>::unconfirmed(IncrementalSmoother<G>& smoother, Closure* c, double bound,
                               bool at_the_end) {
  if (!unconfirmedBy(smoother, c, bound, at_the_end)) return false;
  dropUnconfirmed(smoother, c);
  return true;
}

template <class G>
void OnlineGnc<G>::dropUnconfirmed(IncrementalSmoother<G>& smoother, Closure* c) {
  setWeight(smoother, c, 0.0);
  ++totals_.unconfirmed;
}

template <class G>
double OnlineGnc<G>::endBound() const {
  return c2_end_ > 0 ? std::min(c2_, c2_end_) : c2_;
}

template <class G>
int OnlineGnc<G>::confirmAll(IncrementalSmoother<G>& smoother, std::vector<char>* dropped) {
  int changed = 0;
  dropped->assign(closures_.size(), 0);
  keepHeldJoints(smoother);
  c2_end_ = endThreshold(smoother);
  const double bound = c2_end_ < c2_ ? robust_constants::kEndConfirmMargin * c2_end_
                                     : robust_constants::kFinalConfirmMargin * c2_;
  std::vector<std::pair<double, int>> over;  // (m₋, id) past the bound, unbacked
  for (size_t id = 0; id < closures_.size(); ++id) {
    Closure& c = closures_[id];
    if (!judgedByL(smoother, c) || backed(c, &smoother)) continue;
    c.judged_c2 = c2_;  // as unconfirmedBy
    const std::optional<double> m = innovationPast(smoother, c, bound, /*at_the_end=*/true);
    if (m) over.emplace_back(*m, static_cast<int>(id));
  }
  for (int id : dropLargestPerPose(smoother, std::move(over))) {
    (*dropped)[static_cast<size_t>(id)] = 1;
    ++changed;
  }
  return changed;
}

// The largest first; one drop per pose (smallGrid3D with 90% local false closures: the false
// (1, 27) and the true (1, 8) both past the bound, both dropped, and (1, 8) taken back a round
// later).
template <class G>
std::vector<int> OnlineGnc<G>::dropLargestPerPose(IncrementalSmoother<G>& smoother,
                                                  std::vector<std::pair<double, int>> over) {
  std::sort(over.begin(), over.end(), [](const auto& a, const auto& b) {
    return a.first > b.first || (a.first == b.first && a.second < b.second);
  });
  std::set<int> poses;  // the ends of these drops
  std::vector<int> ids;
  for (const auto& [m, id] : over) {
    Closure& c = closures_[static_cast<size_t>(id)];
    if (poses.count(c.i) > 0 || poses.count(c.j) > 0) continue;
    poses.insert(c.i);
    poses.insert(c.j);
    dropUnconfirmed(smoother, &c);
    ids.push_back(id);
  }
  return ids;
}

// The (L) of finalize() and of the end's scale are of factors the tree holds: their joints
// from one walk down the tree, not a path solve per pose (sphere_bignoise: the end's samples
// took 11 of finalize()'s 19 s).
template <class G>
void OnlineGnc<G>::keepHeldJoints(const IncrementalSmoother<G>& smoother) const {
  std::vector<std::pair<int, int>> held;
  for (const Factor<G>& f : smoother.factors())
    if (const Edge* e = f.relativePose(); e != nullptr && f.inlierWeight() > 0)
      held.emplace_back(e->i, e->j);
  smoother.keepSharedCliqueJoints(held);
}

template <class G>
int OnlineGnc<G>::readEndScaleOnTheWay(IncrementalSmoother<G>& smoother, double update_flops) {
  if (!options_.on(RobustRule::kEndScale) || !confirmsAtTheEnd()) return 0;
  flops_since_reading_ += update_flops;
  const int poses = smoother.numPoses();
  if (poses < next_reading_ ||
      flops_since_reading_ < robust_constants::kEndScaleWork * smoother.factorizationFlops())
    return 0;
  flops_since_reading_ = 0;
  next_reading_ = static_cast<int>(std::ceil(robust_constants::kEndScaleGrowth * poses));
  keepHeldJoints(smoother);
  c2_end_ = endThreshold(smoother);
  if (c2_end_ >= c2_) return 0;
  const double bound = robust_constants::kFinalConfirmMargin * c2_end_;
  std::vector<std::pair<double, int>> over;  // (m₋, id) past the bound
  for (size_t id = 0; id < closures_.size(); ++id)
    if (const auto m = unconfirmedBy(smoother, &closures_[id], bound, /*at_the_end=*/true))
      over.emplace_back(*m, static_cast<int>(id));
  const std::vector<int> ids = dropLargestPerPose(smoother, std::move(over));
  for (int id : ids) closures_[static_cast<size_t>(id)].dropped_on_the_way = true;
  if (!ids.empty()) dropped_on_the_way_ = true;
  return static_cast<int>(ids.size());
}

// The end's scale: σ²_med of the settled inliers' (L) (a minority of false closures sits in
// its tail), times the tail's reach past the median in the trusted edges' (L) (no false edge
// among them); c² from it as on entry, never above the c² in use.
template <class G>
double OnlineGnc<G>::endThreshold(const IncrementalSmoother<G>& smoother) const {
  if (!options_.on(RobustRule::kEndScale)) return c2_;
  const size_t cap = static_cast<size_t>(robust_constants::kEndScaleSamples);
  const auto& factors = smoother.factors();
  std::vector<int> inliers, trusted;
  for (const Closure& c : closures_)
    if (c.state == State::kSettled && c.weight == 1.0 && !c.held && c.factor >= 0 &&
        c.factor < smoother.numFactors() && c.kernel == KernelKind::kTruncatedLeastSquares)
      inliers.push_back(c.factor);
  for (size_t f = 0; f < factors.size(); ++f) {
    const int id = closureOf(static_cast<int>(f));
    const bool trusted_closure =
        id >= 0 && closures_[static_cast<size_t>(id)].state == State::kTrusted;
    if (factors[f].relativePose() != nullptr && factors[f].inlierWeight() == 1.0 &&
        (id < 0 || trusted_closure))
      trusted.push_back(static_cast<int>(f));
  }
  // At most `cap` of each, one in every ⌈n/cap⌉.
  auto sample = [&](const std::vector<int>& fs) {
    std::vector<double> m;
    const size_t stride = std::max<size_t>(1, (fs.size() + cap - 1) / cap);
    for (size_t k = 0; k < fs.size(); k += stride) {
      const Edge& e = *factors[static_cast<size_t>(fs[k])].relativePose();
      if (const std::optional<double> l = leaveOneOutInnovation(smoother, e, Paths::kKept))
        m.push_back(*l);
    }
    return m;
  };
  std::vector<double> m_in = sample(inliers), m_tr = sample(trusted);
  const size_t enough = static_cast<size_t>(robust_constants::kScaleMinSamples);
  if (m_in.size() < enough || m_tr.size() < enough) return c2_;
  const NoiseScaleEstimate in = estimateNoiseScale(std::move(m_in), cuts_, scale_options_, true);
  const NoiseScaleEstimate tr = estimateNoiseScale(std::move(m_tr), cuts_, scale_options_, true);
  if (!in.estimated || !tr.estimated) return c2_;
  const double sigma2 = in.median_sigma2 * tr.sigma2 / tr.median_sigma2;
  const double c2 = scale_options_.tail_factor * c2_given_ * sigma2;
  const double gap = dropped_on_the_way_ ? 1.0 : robust_constants::kEndScaleGap;
  return c2 * gap < c2_ ? c2 : c2_;
}

template <class G>
bool OnlineGnc<G>::binaryKernel(const Closure& c) const {
  return c.kernel == KernelKind::kTruncatedLeastSquares || c.kernel == KernelKind::kGemanMcClure;
}

template <class G>
RobustKernel OnlineGnc<G>::kernelAt(const Closure& c, double mu) const {
  return RobustKernel{c.kernel, c2_, mu};
}

template <class G>
double OnlineGnc<G>::finalWeight(const Closure& c, double s) const {
  if (c.kernel == KernelKind::kTruncatedLeastSquares) return s <= c2_ ? 1.0 : 0.0;
  return kernelAt(c, 1.0).weight(s);
}

template <class G>
bool OnlineGnc<G>::isInlier(const Closure& c) const {
  return c.weight >= kernelAt(c, 1.0).inlierCut();
}

// The first check: s ≤ c² settles at weight 1 (no graduation); otherwise the convex surrogate
// at μ₀ = initialMu(s) and w₀ = ρ′_μ₀(s) (Huber, Cauchy: w₀ = ρ′(s)).
template <class G>
void OnlineGnc<G>::enter(Closure* c, double s, double m, bool may_reject) {
  c->s = s;
  c->judged_c2 = c2_;
  c->steps = 0;
  if (m <= c2_) {
    c->state = State::kSettled;
    c->weight = 1.0;
    return;
  }
  if (may_reject && binaryKernel(*c) && m > robust_constants::kEntryBand * c2_) {
    c->state = State::kSettled;
    c->weight = 0.0;
    return;
  }
  const RobustKernel k = kernelAt(*c, 1.0);
  c->mu = k.isGraduated() ? k.initialMu(s) : 1.0;
  c->weight = kernelAt(*c, c->mu).weight(s);
  c->state = State::kGraduating;
}

// One step: μ moves one notch towards the kernel, w = ρ′_μ(s). Settled when the surrogate's
// weight is the kernel's (TLS: binary, or μ ≥ max_mu; GM: μ = 1; Huber, Cauchy: w stopped
// moving), or after max_steps_per_closure steps (then the kernel's own weight).
template <class G>
double OnlineGnc<G>::graduate(Closure* c, double s) {
  c->s = s;
  ++c->steps;
  const RobustKernel now = kernelAt(*c, c->mu);
  double w;
  bool settled;
  if (now.isGraduated()) {
    c->mu = now.nextMu(options_.mu_step);
    const RobustKernel next = kernelAt(*c, c->mu);
    w = next.weight(s);
    settled = c->kernel == KernelKind::kTruncatedLeastSquares
                  ? (w == 0.0 || w == 1.0 || c->mu >= robust_constants::kMaxMu)
                  : next.atKernel();
  } else {
    w = now.weight(s);
    settled = std::abs(w - c->weight) < robust_constants::kWeightTolerance;
  }
  if (!settled && c->steps >= options_.max_steps_per_closure) {
    w = finalWeight(*c, s);
    settled = true;
  }
  if (settled && c->kernel == KernelKind::kTruncatedLeastSquares) w = finalWeight(*c, s);
  if (settled) c->state = State::kSettled;
  return w;
}

template <class G>
double OnlineGnc<G>::residual(const IncrementalSmoother<G>& smoother, const Closure& c) const {
  const Factor<G>& f = smoother.factors()[static_cast<size_t>(c.factor)];
  return f.relativePose()->cost(smoother.estimate(c.i), smoother.estimate(c.j));
}

template <class G>
void OnlineGnc<G>::setWeight(IncrementalSmoother<G>& smoother, Closure* c, double w) {
  c->weight = w;
  smoother.setFactorWeight(c->factor, w);
}

template <class G>
double OnlineGnc<G>::admit(const IncrementalSmoother<G>& smoother, Key from, Key to,
                           EdgeTrust trust, bool structural, const Edge& edge, KernelKind kernel) {
  if (odometry(from, to) && trust != EdgeTrust::kRobust) return 1.0;  // odometry: not judged
  const int id = static_cast<int>(closures_.size());
  closures_.emplace_back();
  Closure& c = closures_.back();
  c.kernel = kernel == KernelKind::kNone ? options_.kernel : kernel;
  c.from = from;
  c.to = to;
  c.i = edge.i;
  c.j = edge.j;
  c.z = edge.measurement;
  c.covariance = edge.information.inverse();
  if (trust == EdgeTrust::kTrusted || structural) {
    c.state = State::kTrusted;
  } else {
    const double s = edge.cost(smoother.estimate(edge.i), smoother.estimate(edge.j));
    const double m = innovation(smoother, edge, s);
    observe(smoother, id, m);
    if (!scaleKnown() && options_.on(RobustRule::kWarmUp) && binaryKernel(c)) {
      c.state = State::kSettled;  // out of the tree until σ̂² exists (judgeHeld)
      c.weight = 0.0;
      c.judged_c2 = c2_;
      c.held = true;
    } else {
      enter(&c, s, m, /*may_reject=*/true);
    }
  }
  unresolved_.push_back(id);
  if (c.state == State::kGraduating) graduating_.push_back(id);
  if (c.held) held_.push_back(id);
  return c.weight;
}

template <class G>
void OnlineGnc<G>::match(const IncrementalSmoother<G>& smoother, int first, std::vector<int>* ids) {
  if (ids->empty()) return;
  std::map<std::pair<int, int>, std::vector<int>> wanted;
  for (int id : *ids) wanted[{closures_[id].i, closures_[id].j}].push_back(id);
  const auto& factors = smoother.factors();
  by_factor_.resize(factors.size(), -1);
  for (size_t f = static_cast<size_t>(first); f < factors.size(); ++f) {
    const Edge* e = factors[f].relativePose();
    if (!e) continue;
    auto it = wanted.find({e->i, e->j});
    if (it == wanted.end()) continue;
    for (int& id : it->second) {
      if (id < 0 || !samePose(closures_[id].z, e->measurement)) continue;
      closures_[id].factor = static_cast<int>(f);
      by_factor_[f] = id;
      id = -1;
      break;
    }
  }
  std::vector<int> left;
  for (auto& [pair, list] : wanted)
    for (int id : list)
      if (id >= 0) left.push_back(id);
  ids->swap(left);  // still queued (not added by this update)
}

template <class G>
void OnlineGnc<G>::resolve(const IncrementalSmoother<G>& smoother) {
  match(smoother, resolved_factors_, &unresolved_);
  resolved_factors_ = smoother.numFactors();
}

template <class G>
void OnlineGnc<G>::remap(const IncrementalSmoother<G>& smoother) {
  std::vector<int> all;
  for (size_t id = 0; id < closures_.size(); ++id) {
    closures_[id].factor = -1;
    all.push_back(static_cast<int>(id));
  }
  by_factor_.assign(smoother.factors().size(), -1);
  match(smoother, 0, &all);
  unresolved_ = all;
  resolved_factors_ = smoother.numFactors();
}

// Kept at Ω's word: s at the final estimate, the closure out of it (weight 0), against the
// given c². Taken back, it is in the next relinearisation's estimate, which the caller makes.
template <class G>
int OnlineGnc<G>::takeBackAtWord(IncrementalSmoother<G>& smoother) {
  int taken = 0;
  for (Closure& c : closures_) {
    if (c.state != State::kSettled || c.factor < 0 || c.held || c.weight != 0.0 || !binaryKernel(c))
      continue;
    c.s = residual(smoother, c);
    if (!(c.s <= c2_given_)) continue;
    setWeight(smoother, &c, 1.0);
    ++taken;
  }
  totals_.kept_at_word += taken;
  return taken;
}

template <class G>
int OnlineGnc<G>::sweepInliers(IncrementalSmoother<G>& smoother) {
  sweep_due_ = false;
  int changed = 0;
  for (size_t k = 0; k < closures_.size(); ++k) {
    Closure& c = closures_[k];
    if (c.state != State::kSettled || c.factor < 0 || c.held || !isInlier(c)) continue;
    const double s = residual(smoother, c);
    c.s = s;
    if (s <= robust_constants::kRecheckMargin * c2_) continue;
    enter(&c, s, s, /*may_reject=*/false);
    changed += takeRecheck(smoother, static_cast<int>(k));
  }
  return changed;
}

// Held closures are at weight 0, out of Σ: (E) is their innovation against the estimate without
// them, as for any closure on entry. Their innovations were recorded when they arrived.
template <class G>
int OnlineGnc<G>::judgeHeld(IncrementalSmoother<G>& smoother, size_t at_most) {
  int changed = 0;
  std::vector<int> still;
  size_t judged = 0;
  for (int id : held_) {
    Closure& c = closures_[id];
    if (judged >= at_most) {
      still.push_back(id);
      continue;
    }
    if (!c.held || c.state == State::kExcluded) {  // excluded meanwhile
      c.held = false;
      continue;
    }
    if (c.factor < 0) {
      still.push_back(id);
      continue;
    }
    c.held = false;
    ++judged;
    const double s = residual(smoother, c);
    enter(
        &c, s,
        innovation(smoother, *smoother.factors()[static_cast<size_t>(c.factor)].relativePose(), s),
        /*may_reject=*/true);
    if (c.state == State::kGraduating) graduating_.push_back(id);
    if (c.weight != 0.0) {
      smoother.setFactorWeight(c.factor, c.weight);
      ++changed;
    }
  }
  held_.swap(still);
  return changed;
}

template <class G>
int OnlineGnc<G>::step(IncrementalSmoother<G>& smoother, StepScope scope) {
  const bool recheck_all = scope != StepScope::kRoundRobin;
  int changed = 0;
  // The warm-up's closures, once σ̂² is there (in finalize() whether or not it is).
  if (!held_.empty() && (recheck_all || scaleKnown())) changed += judgeHeld(smoother);
  // In finalize(): every inlier no inlier agrees with, (L) at final_confirm_margin·c².
  std::vector<char> dropped;
  if (scope == StepScope::kFinalize && confirmsAtTheEnd())
    changed += confirmAll(smoother, &dropped);
  // The graduating closures: one step each (those not in the smoother yet keep w₀).
  std::vector<int> still;
  for (int id : graduating_) {
    Closure& c = closures_[id];
    if (c.state != State::kGraduating) continue;  // excluded meanwhile
    if (c.factor < 0) {
      still.push_back(id);
      continue;
    }
    const double w = graduate(&c, residual(smoother, c));
    if (w != c.weight) {
      setWeight(smoother, &c, w);
      ++changed;
      ++totals_.graduation_steps;
    }
    if (c.state == State::kGraduating) still.push_back(id);
  }
  graduating_.swap(still);
  // c² shrunk by recheck_margin: every settled inlier at once, not in the round robin's turn.
  if (sweep_due_) changed += sweepInliers(smoother);
  // The settled closures, at the kernel: an outlier the estimate now agrees with comes back, an
  // inlier beyond recheck_margin·c² graduates again (the "affected" closures, header comment).
  const size_t n = closures_.size();
  const size_t budget = recheck_all ? n : static_cast<size_t>(options_.rechecks_per_update);
  for (size_t k = 0, looked = 0; k < budget && looked < n; ++looked) {
    const int id = static_cast<int>(cursor_++ % n);
    Closure& c = closures_[id];
    if (c.state != State::kSettled || c.factor < 0 || c.held) continue;
    if (static_cast<size_t>(id) < dropped.size() && dropped[static_cast<size_t>(id)]) continue;
    ++k;
    ++totals_.rechecks;
    const double s = residual(smoother, c);
    c.s = s;
    const bool inlier = isInlier(c);
    if (!inlier && c.weight == 0.0 && options_.entry == EntryTest::kInnovation && binaryKernel(c)) {
      // A closure at weight 0 is not in Σ: its innovation is (E) again, judged as on entry
      // against the c² in use now — once that has grown by a tenth since it was last judged
      // (σ̂² after the warm-up), and in finalize() (a path to the root each: not every update).
      if (!recheck_all && c2_ <= 1.1 * c.judged_c2) continue;
      const bool at_the_end = scope == StepScope::kFinalize;
      if (at_the_end && c.end_take_backs >= kEndTakeBacks) continue;
      c.judged_c2 = c2_;
      const Edge& edge = *smoother.factors()[static_cast<size_t>(c.factor)].relativePose();
      // A closure the end's scale dropped on the way is taken back by it, as in finalize().
      const double bound = at_the_end || c.dropped_on_the_way ? endBound() : c2_;
      // Out by (E) = m past the bound; it holds for m when it holds for m's lower bound (the
      // poses' marginals, no path solve), which comes first where the paths are kept (the
      // marginals come from them).
      auto staysOut = [&](double m) { return m > bound; };
      if (recheck_all && staysOut(innovationLowerBound(smoother, edge, s))) {
        ++totals_.rechecks_bounded;
        continue;
      }
      if (staysOut(innovation(smoother, edge, s, recheck_all ? Paths::kKept : Paths::kOnce)))
        continue;
      c.state = State::kSettled;
      if (at_the_end) ++c.end_take_backs;
      setWeight(smoother, &c, 1.0);
      ++totals_.regraduated;
      ++changed;
      continue;
    }
    const bool flip = s > robust_constants::kRecheckMargin * c2_ ? inlier : !inlier;
    const bool drift =
        c.kernel != KernelKind::kTruncatedLeastSquares && c.kernel != KernelKind::kGemanMcClure &&
        std::abs(finalWeight(c, s) - c.weight) > 10 * robust_constants::kWeightTolerance;
    if (!flip && !drift) continue;
    if (inlier || drift) {
      enter(&c, s, s, /*may_reject=*/false);
    } else {  // an outlier the estimate now agrees with: back at weight 1
      c.state = State::kSettled;
      c.weight = 1.0;
    }
    changed += takeRecheck(smoother, id);
  }
  return changed;
}

// A re-check's new state, taken in: graduating again, or its weight set in the smoother.
template <class G>
int OnlineGnc<G>::takeRecheck(IncrementalSmoother<G>& smoother, int id) {
  Closure& c = closures_[static_cast<size_t>(id)];
  if (c.state == State::kGraduating) graduating_.push_back(id);
  ++totals_.regraduated;
  if (smoother.factors()[static_cast<size_t>(c.factor)].inlierWeight() == c.weight) return 0;
  setWeight(smoother, &c, c.weight);
  return 1;
}

template <class G>
int OnlineGnc<G>::closureOf(int factor) const {
  if (factor < 0 || static_cast<size_t>(factor) >= by_factor_.size()) return -1;
  return by_factor_[static_cast<size_t>(factor)];
}

template <class G>
void OnlineGnc<G>::exclude(IncrementalSmoother<G>& smoother, int factor) {
  if (factor < 0 || factor >= smoother.numFactors())
    throw std::invalid_argument("OnlineGnc::exclude: factor " + std::to_string(factor) +
                                " out of range (" + std::to_string(smoother.numFactors()) +
                                " factors)");
  const int id = closureOf(factor);
  if (id < 0 || closures_[id].state == State::kTrusted) return;
  closures_[id].state = State::kExcluded;  // dropped from graduating_ by the next step()
}

template <class G>
void OnlineGnc<G>::include(IncrementalSmoother<G>& smoother, int factor) {
  if (factor < 0 || factor >= smoother.numFactors())
    throw std::invalid_argument("OnlineGnc::include: factor " + std::to_string(factor) +
                                " out of range (" + std::to_string(smoother.numFactors()) +
                                " factors)");
  const int id = closureOf(factor);
  if (id < 0 || closures_[id].state != State::kExcluded) return;
  Closure& c = closures_[id];
  const double s = residual(smoother, c);
  enter(&c, s,
        innovation(smoother, *smoother.factors()[static_cast<size_t>(c.factor)].relativePose(), s),
        /*may_reject=*/true);
  if (c.state == State::kGraduating) graduating_.push_back(id);
  smoother.setFactorWeight(c.factor, c.weight);
}

template <class G>
ClosureCounts OnlineGnc<G>::counts() const {
  ClosureCounts out = totals_;
  for (const Closure& c : closures_) {
    switch (c.state) {
      case State::kTrusted:
        ++out.trusted;
        break;
      case State::kExcluded:
        ++out.excluded;
        break;
      default:
        ++(isInlier(c) ? out.inlier : out.outlier);
        if (c.state == State::kGraduating || c.held) ++out.graduating;
    }
  }
  return out;
}

template <class G>
bool OnlineGnc<G>::judges(int factor) const {
  const int id = closureOf(factor);
  return id >= 0 &&
         (closures_[id].state == State::kGraduating || closures_[id].state == State::kSettled);
}

template <class G>
bool OnlineGnc<G>::settledInlier(int factor) const {
  const int id = closureOf(factor);
  if (id < 0) return false;
  const Closure& c = closures_[id];
  return c.state == State::kSettled && !c.held && isInlier(c);
}

template <class G>
KernelKind OnlineGnc<G>::kernelOf(int factor) const {
  return judges(factor) ? closures_[closureOf(factor)].kernel : KernelKind::kNone;
}

template <class G>
double OnlineGnc<G>::rho(int factor, double s) const {
  if (!judges(factor)) return s;
  const Closure& c = closures_[closureOf(factor)];
  if (c.kernel == KernelKind::kTruncatedLeastSquares) return std::min(s, c2_);
  return kernelAt(c, 1.0).rho(s);
}

template <class G>
std::vector<ClosureReport> OnlineGnc<G>::closures() const {
  std::vector<ClosureReport> out;
  out.reserve(closures_.size());
  for (const Closure& c : closures_) {
    ClosureReport r;
    r.from = c.from;
    r.to = c.to;
    r.weight = c.weight;
    r.residual = c.s;
    r.graduating = c.state == State::kGraduating || c.held;
    r.steps = c.steps;
    r.factor = c.factor;
    r.kernel = c.kernel;
    switch (c.state) {
      case State::kTrusted:
        r.status = ClosureStatus::kTrusted;
        break;
      case State::kExcluded:
        r.status = ClosureStatus::kExcluded;
        break;
      default:
        r.status = isInlier(c) ? ClosureStatus::kInlier : ClosureStatus::kOutlier;
    }
    out.push_back(r);
  }
  return out;
}

template class OnlineGnc<SE2>;
template class OnlineGnc<SE3>;

}  // namespace arbor
