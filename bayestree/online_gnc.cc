#include "arbor_slam/bayestree/online_gnc.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>

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

// The members defined here; online_gnc_scale.cc and online_gnc_end.cc instantiate theirs.
template class OnlineGnc<SE2>;
template class OnlineGnc<SE3>;

}  // namespace arbor
