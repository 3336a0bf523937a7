// OnlineGnc, part two: the noise scale and the consistency of pairs (P): every closure's
// innovation recorded, its neighbours within corroboration_window asked whether they agree, σ̂²
// and the c² in use estimated again (online_gnc.h, "the noise scale", "corroboration"). The
// estimator itself is bayestree/noise_scale.h.
#include "arbor_slam/bayestree/online_gnc.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <utility>
#include <vector>

namespace arbor {
namespace {

// The sample count at which an estimate re-made from n samples is made next: every new one up
// to 64, then when their number has grown by an eighth (O(k) each, O(k) in all).
size_t nextEstimateAt(size_t n) { return n < 64 ? n + 1 : n + n / 8; }

}  // namespace

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

// The members above, for the two groups (online_gnc.cc instantiates the rest).
template void OnlineGnc<SE2>::observe(const IncrementalSmoother<SE2>& smoother, int id, double m);
template void OnlineGnc<SE3>::observe(const IncrementalSmoother<SE3>& smoother, int id, double m);
template const std::vector<double>* OnlineGnc<SE2>::scaleSource() const;
template const std::vector<double>* OnlineGnc<SE3>::scaleSource() const;
template double OnlineGnc<SE2>::pairS(const IncrementalSmoother<SE2>& smoother, const Closure& a,
                                      const Closure& b) const;
template double OnlineGnc<SE3>::pairS(const IncrementalSmoother<SE3>& smoother, const Closure& a,
                                      const Closure& b) const;
template double OnlineGnc<SE2>::pairS(const IncrementalSmoother<SE2>& smoother, const Closure& a,
                                      const Closure& b, const SE2& xa, const SE2& xb) const;
template double OnlineGnc<SE3>::pairS(const IncrementalSmoother<SE3>& smoother, const Closure& a,
                                      const Closure& b, const SE3& xa, const SE3& xb) const;
template double OnlineGnc<SE2>::pairSBothWays(const IncrementalSmoother<SE2>& smoother,
                                              const Closure& a, const Closure& b) const;
template double OnlineGnc<SE3>::pairSBothWays(const IncrementalSmoother<SE3>& smoother,
                                              const Closure& a, const Closure& b) const;
template bool OnlineGnc<SE2>::agree(const IncrementalSmoother<SE2>& smoother, const Closure& a,
                                    const Closure& b, const SE2& xa, const SE2& xb);
template bool OnlineGnc<SE3>::agree(const IncrementalSmoother<SE3>& smoother, const Closure& a,
                                    const Closure& b, const SE3& xa, const SE3& xb);
template bool OnlineGnc<SE2>::scaleKnown() const;
template bool OnlineGnc<SE3>::scaleKnown() const;
template bool OnlineGnc<SE2>::recordsPartners() const;
template bool OnlineGnc<SE3>::recordsPartners() const;
template bool OnlineGnc<SE2>::spansLoop(const Closure& c) const;
template bool OnlineGnc<SE3>::spansLoop(const Closure& c) const;
template bool OnlineGnc<SE2>::backed(const Closure& c, const IncrementalSmoother<SE2>* now) const;
template bool OnlineGnc<SE3>::backed(const Closure& c, const IncrementalSmoother<SE3>* now) const;

}  // namespace arbor
