// OnlineGnc, part three: the end pass (online_gnc.h, "confirmed at the end", "the end's scale",
// "kept at Ω's word"): the leave-one-out innovation (L) of the settled inliers, the end's scale
// read from (L) at the whole graph's estimate, on the way and in finalize(), and the rejected
// closures taken back at Ω's word.
#include "arbor_slam/bayestree/online_gnc.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <set>
#include <utility>
#include <vector>

#include "arbor_slam/bayestree/closure_innovation.h"

namespace arbor {
template <class G>
bool OnlineGnc<G>::confirmsAtTheEnd() const {
  // Without corroboration (K = 0) no closure is backed, and true closures in runs sit up to
  // 2.7·c² by (L): the garage lost three more at K = 0 (F_clean 1.0092 → 1.0184).
  return options_.on(RobustRule::kFinalConfirm) && options_.corroboration_window > 0 &&
         options_.entry == EntryTest::kInnovation && estimate_.estimated;
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

// The members above, for the two groups (online_gnc.cc instantiates the rest).
template bool OnlineGnc<SE2>::confirmsAtTheEnd() const;
template bool OnlineGnc<SE3>::confirmsAtTheEnd() const;
template bool OnlineGnc<SE2>::judgedByL(const IncrementalSmoother<SE2>& smoother,
                                        const Closure& c) const;
template bool OnlineGnc<SE3>::judgedByL(const IncrementalSmoother<SE3>& smoother,
                                        const Closure& c) const;
template std::optional<double> OnlineGnc<SE2>::innovationPast(
    const IncrementalSmoother<SE2>& smoother, const Closure& c, double bound,
    bool at_the_end) const;
template std::optional<double> OnlineGnc<SE3>::innovationPast(
    const IncrementalSmoother<SE3>& smoother, const Closure& c, double bound,
    bool at_the_end) const;
template std::optional<double> OnlineGnc<SE2>::unconfirmedBy(
    const IncrementalSmoother<SE2>& smoother, Closure* c, double bound, bool at_the_end);
template std::optional<double> OnlineGnc<SE3>::unconfirmedBy(
    const IncrementalSmoother<SE3>& smoother, Closure* c, double bound, bool at_the_end);
template bool OnlineGnc<SE2>::unconfirmed(IncrementalSmoother<SE2>& smoother, Closure* c,
                                          double bound, bool at_the_end);
template bool OnlineGnc<SE3>::unconfirmed(IncrementalSmoother<SE3>& smoother, Closure* c,
                                          double bound, bool at_the_end);
template void OnlineGnc<SE2>::dropUnconfirmed(IncrementalSmoother<SE2>& smoother, Closure* c);
template void OnlineGnc<SE3>::dropUnconfirmed(IncrementalSmoother<SE3>& smoother, Closure* c);
template double OnlineGnc<SE2>::endBound() const;
template double OnlineGnc<SE3>::endBound() const;
template int OnlineGnc<SE2>::confirmAll(IncrementalSmoother<SE2>& smoother,
                                        std::vector<char>* dropped);
template int OnlineGnc<SE3>::confirmAll(IncrementalSmoother<SE3>& smoother,
                                        std::vector<char>* dropped);
template std::vector<int> OnlineGnc<SE2>::dropLargestPerPose(
    IncrementalSmoother<SE2>& smoother, std::vector<std::pair<double, int>> over);
template std::vector<int> OnlineGnc<SE3>::dropLargestPerPose(
    IncrementalSmoother<SE3>& smoother, std::vector<std::pair<double, int>> over);
template void OnlineGnc<SE2>::keepHeldJoints(const IncrementalSmoother<SE2>& smoother) const;
template void OnlineGnc<SE3>::keepHeldJoints(const IncrementalSmoother<SE3>& smoother) const;
template int OnlineGnc<SE2>::readEndScaleOnTheWay(IncrementalSmoother<SE2>& smoother,
                                                  double update_flops);
template int OnlineGnc<SE3>::readEndScaleOnTheWay(IncrementalSmoother<SE3>& smoother,
                                                  double update_flops);
template double OnlineGnc<SE2>::endThreshold(const IncrementalSmoother<SE2>& smoother) const;
template double OnlineGnc<SE3>::endThreshold(const IncrementalSmoother<SE3>& smoother) const;
template int OnlineGnc<SE2>::takeBackAtWord(IncrementalSmoother<SE2>& smoother);
template int OnlineGnc<SE3>::takeBackAtWord(IncrementalSmoother<SE3>& smoother);

}  // namespace arbor
