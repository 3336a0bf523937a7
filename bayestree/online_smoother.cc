#include "arbor_slam/bayestree/online_smoother.h"

#include <array>
#include <chrono>
#include <cmath>
#include <stdexcept>

#include "arbor_slam/core/factor_error.h"
#include "arbor_slam/core/finite_pose.h"
#include "arbor_slam/core/information.h"
#include "arbor_slam/core/rigid_alignment.h"

namespace arbor {
namespace {

void addStats(UpdateStats* total, const UpdateStats& s) {
  addUpdateCounts(total, s);
  total->async_pending = s.async_pending;  // the state after the last update
  total->time_s += s.time_s;
}

}  // namespace

const char* toString(EdgeStatus status) {
  switch (status) {
    case EdgeStatus::kAccepted:
      return "accepted";
    case EdgeStatus::kDuplicate:
      return "duplicate";
    case EdgeStatus::kPending:
      return "pending";
    case EdgeStatus::kRejected:
      return "rejected";
  }
  return "unknown";
}

const char* toString(EdgeSwitchStatus status) {
  switch (status) {
    case EdgeSwitchStatus::kApplied:
      return "applied";
    case EdgeSwitchStatus::kUnknownPose:
      return "unknown pose";
    case EdgeSwitchStatus::kNoSuchEdge:
      return "no such edge";
    case EdgeSwitchStatus::kAlreadyDisabled:
      return "already disabled";
    case EdgeSwitchStatus::kAlreadyEnabled:
      return "already enabled";
    case EdgeSwitchStatus::kBridge:
      return "bridge";
  }
  return "unknown";
}

template <class G>
OnlineSmoother<G>::OnlineSmoother(OnlineSmootherOptions<G> options)
    : options_(options), smoother_(options.smoother) {
  if (!allFinite(options_.gauge))
    throw std::invalid_argument("OnlineSmoother: gauge pose not finite");
  // The robust layer judges each closure against the estimate; with async relinearisation that
  // lags the background job and the robust replays end wrecked (docs/design.md).
  if (options_.robust && options_.smoother.relinearize == RelinearizationMode::kAsync)
    throw std::invalid_argument(
        "OnlineSmoother: robust smoothing needs inline relinearisation (not async)");
  if (options_.robust) gnc_.emplace(*options_.robust);  // throws on bad options
}

template <class G>
bool OnlineSmoother<G>::sameMeasurement(const Measurement& a, const Measurement& b) const {
  const double tol = 1e-12;
  if (a.z.localCoordinates(b.z).cwiseAbs().maxCoeff() > tol) return false;
  const double scale = std::max(1.0, a.omega.cwiseAbs().maxCoeff());
  return (a.omega - b.omega).cwiseAbs().maxCoeff() <= tol * scale;
}

template <class G>
bool OnlineSmoother<G>::setInitialGuess(Key id, const G& value) {
  if (!allFinite(value) || index_.count(id)) return false;
  guesses_.insert_or_assign(id, value);
  return true;
}

template <class G>
int OnlineSmoother<G>::createPose(Key id, const G& computed, int creator, bool anchor) {
  G value = computed;
  if (auto guess = guesses_.find(id); guess != guesses_.end()) {
    value = guess->second;
    guesses_.erase(guess);
  }
  const int index =
      creator < 0 && anchor ? smoother_.addFixedPose(value) : smoother_.addPose(value);
  index_.emplace(id, index);
  ids_.push_back(id);
  creator_.push_back(creator);
  component_parent_.push_back(creator < 0 ? index : root(creator));
  components_.emplace_back();
  if (creator < 0) {
    Component& c = components_[index];
    c.members = {index};
    c.first = index;
    c.anchor = anchor ? index : -1;
    ++stats_.components;
  } else {
    components_[root(creator)].members.push_back(index);
  }
  ++stats_.poses;
  return index;
}

template <class G>
int OnlineSmoother<G>::root(int v) const {
  while (component_parent_[v] != v)
    v = component_parent_[v] = component_parent_[component_parent_[v]];
  return v;
}

template <class G>
G OnlineSmoother<G>::moveOntoPriors(const Component& c) const {
  if (c.pose_prior_pose >= 0)
    return c.pose_prior_target.compose(smoother_.estimate(c.pose_prior_pose).inverse());
  std::vector<typename G::Translation> estimated;
  for (int v : c.position_prior_poses) estimated.push_back(smoother_.estimate(v).translation());
  return rigidAlignment<G>(estimated, c.position_prior_values, c.position_prior_weights);
}

// When priors come to fix a component's gauge, the component first moves rigidly into their
// frame (a pose prior's pose onto its value, or the weighted Kabsch fit of its estimated
// positions onto the position priors), so that the first update without the anchor starts near
// the priors instead of wherever the anchor held it; then the anchor is released.
template <class G>
void OnlineSmoother<G>::releaseAnchorIfFixed(int c) {
  Component& comp = components_[c];
  if (comp.anchor < 0 || !comp.gauge.fixesGauge()) return;
  smoother_.transformPoses(comp.members, moveOntoPriors(comp));
  smoother_.releaseFixedPose(comp.anchor);
  comp.anchor = -1;
  ++stats_.anchors_released;
}

// Joining two components by the edge from → to with measurement z. The one that keeps its frame
// ("keep"): the one whose priors fix its gauge, else the older. The other ("move"), unless its
// priors fix its gauge too, moves rigidly so that the edge holds exactly at the current
// estimates: T = x_from z x_to⁻¹ (moving to's side) or x_to z⁻¹ x_from⁻¹ (moving from's side).
// Its anchor is released: the joined component keeps one.
template <class G>
void OnlineSmoother<G>::join(int from, int to, const G& z) {
  const int a = root(from), b = root(to);
  const bool world_a = components_[a].gauge.fixesGauge(),
             world_b = components_[b].gauge.fixesGauge();
  const bool keep_a = world_a != world_b ? world_a : components_[a].first < components_[b].first;
  const int keep = keep_a ? a : b, move = keep_a ? b : a;
  if (!components_[move].gauge.fixesGauge()) {
    const G T = keep_a
                    ? smoother_.estimate(from).compose(z).compose(smoother_.estimate(to).inverse())
                    : smoother_.estimate(to)
                          .compose(z.inverse())
                          .compose(smoother_.estimate(from).inverse());
    smoother_.transformPoses(components_[move].members, T);
  }
  if (components_[move].anchor >= 0) {
    smoother_.releaseFixedPose(components_[move].anchor);
    ++stats_.anchors_released;
  }
  // Union: the members of the smaller list go to the larger one's (O(n log n) over all joins).
  Component moved = std::move(components_[move]);
  components_[move] = Component{};
  Component& kept = components_[keep];
  if (kept.members.size() < moved.members.size()) kept.members.swap(moved.members);
  kept.members.insert(kept.members.end(), moved.members.begin(), moved.members.end());
  kept.gauge.add(moved.gauge);
  if (kept.pose_prior_pose < 0) {
    kept.pose_prior_pose = moved.pose_prior_pose;
    kept.pose_prior_target = moved.pose_prior_target;
  }
  kept.position_prior_poses.insert(kept.position_prior_poses.end(),
                                   moved.position_prior_poses.begin(),
                                   moved.position_prior_poses.end());
  kept.position_prior_values.insert(kept.position_prior_values.end(),
                                    moved.position_prior_values.begin(),
                                    moved.position_prior_values.end());
  kept.position_prior_weights.insert(kept.position_prior_weights.end(),
                                     moved.position_prior_weights.begin(),
                                     moved.position_prior_weights.end());
  kept.first = std::min(kept.first, moved.first);
  component_parent_[move] = keep;
  --stats_.components;
  ++stats_.joins;
  releaseAnchorIfFixed(keep);
}

template <class G>
void OnlineSmoother<G>::apply(const Measurement& m, EdgeTrust trust, KernelKind kernel) {
  auto from = index_.find(m.from);
  auto to = index_.find(m.to);
  // An edge that creates a pose or joins two components holds exactly at the estimate it
  // makes: the robust layer trusts it.
  const bool structural =
      from == index_.end() || to == index_.end() || root(from->second) != root(to->second);
  if (from == index_.end() && to == index_.end()) {  // a new component, anchored at `from`
    const int f = createPose(m.from, options_.gauge, -1);
    createPose(m.to, smoother_.estimate(f).compose(m.z), f);
  } else if (to == index_.end()) {
    createPose(m.to, smoother_.estimate(from->second).compose(m.z), from->second);
  } else if (from == index_.end()) {
    createPose(m.from, smoother_.estimate(to->second).compose(m.z.inverse()), to->second);
  } else if (root(from->second) != root(to->second)) {
    join(from->second, to->second, m.z);
  }
  const auto edge = RelativePoseEdge<G>::make(index_.at(m.from), index_.at(m.to), m.z, m.omega);
  Factor<G> factor(edge);
  if (gnc_)
    factor.setInlierWeight(gnc_->admit(smoother_, m.from, m.to, trust, structural, edge, kernel));
  if (!disabled_pairs_.empty() && disabled_pairs_.count(idPair(m.from, m.to)))
    factor.setInlierWeight(0.0);  // between a pair taken back: disabled until enableEdge
  smoother_.addFactor(factor);
  queued_.push_back(factor);
  ++stats_.edges_accepted;
}

template <class G>
EdgeResult OnlineSmoother<G>::addEdge(Key from, Key to, const G& z, const Matrix& omega,
                                      EdgeTrust trust, KernelKind kernel) {
  auto reject = [&](const std::string& why) {
    ++stats_.edges_rejected;
    return EdgeResult{EdgeStatus::kRejected, why};
  };
  if (!allFinite(z) || !omega.allFinite()) return reject("NaN or infinite value");
  if (from == to) return reject("self-loop on pose " + std::to_string(from));
  const std::string problem = informationProblem(omega);
  if (!problem.empty()) return reject("bad information: " + problem);
  const std::string far = translationProblem(z);
  if (!far.empty()) return reject("bad measurement: " + far);

  Measurement m{from, to, z, omega};
  std::vector<Measurement>& same_pair = seen_[{from, to}];
  for (const Measurement& other : same_pair)
    if (sameMeasurement(m, other)) {
      ++stats_.edges_duplicate;
      return EdgeResult{EdgeStatus::kDuplicate, "repeats an earlier edge " + std::to_string(from) +
                                                    " -> " + std::to_string(to)};
    }
  same_pair.push_back(m);
  apply(m, trust, kernel);
  return EdgeResult{EdgeStatus::kAccepted, ""};
}

template <class G>
EdgeResult OnlineSmoother<G>::addPrior(Key id, const Factor<G>& prior, const G& start) {
  auto it = index_.find(id);
  const bool fixes = prior.kind() == FactorKind::kPosePrior;
  int v;
  if (it == index_.end()) {  // a new component, anchored unless the prior fixes its gauge
    v = createPose(id, start, -1, /*anchor=*/!fixes);
  } else {
    v = it->second;
  }
  Factor<G> f = prior;
  f.setKeys(v);
  smoother_.addFactor(f);
  queued_.push_back(f);
  Component& c = components_[root(v)];
  if (const auto* p = f.positionPrior()) {
    c.gauge.addPositionPrior(p->position, p->information);
    c.position_prior_poses.push_back(v);
    c.position_prior_values.push_back(p->position);
    c.position_prior_weights.push_back(G::kDim / p->information.inverse().trace());
  } else {
    c.gauge.addPosePrior();
    if (c.pose_prior_pose < 0) {
      c.pose_prior_pose = v;
      c.pose_prior_target = start;
    }
  }
  // A component still held by its anchor moves onto its priors as far as they say (a
  // translation for one position, a rotation too for more), so that the anchor and the priors
  // do not pull the estimate far apart while the gauge is not yet fixed.
  if (c.anchor >= 0) smoother_.transformPoses(c.members, moveOntoPriors(c));
  releaseAnchorIfFixed(root(v));
  ++stats_.priors_accepted;
  return EdgeResult{EdgeStatus::kAccepted, ""};
}

template <class G>
EdgeResult OnlineSmoother<G>::addPosePrior(Key id, const G& z, const Matrix& omega,
                                           const G& offset) {
  if (!allFinite(z) || !allFinite(offset) || !omega.allFinite()) {
    ++stats_.priors_rejected;
    return {EdgeStatus::kRejected,
            "pose prior on " + std::to_string(id) + ": NaN or infinite value"};
  }
  try {
    const auto prior = PosePriorFactor<G>::make(0, z, omega, offset);
    return addPrior(id, prior, z.compose(offset.inverse()));
  } catch (const std::invalid_argument& e) {
    ++stats_.priors_rejected;
    return {EdgeStatus::kRejected, "pose prior on " + std::to_string(id) + ": " + e.what()};
  }
}

template <class G>
EdgeResult OnlineSmoother<G>::addPositionPrior(Key id, const typename G::Translation& p,
                                               const PositionMatrix& omega) {
  if (!p.allFinite() || !omega.allFinite()) {
    ++stats_.priors_rejected;
    return {EdgeStatus::kRejected,
            "position prior on " + std::to_string(id) + ": NaN or infinite value"};
  }
  try {
    const auto prior = PositionPriorFactor<G>::make(0, p, omega);
    G start;
    if constexpr (G::kDim == 2)
      start = G(p, 0.0);
    else
      start = G(Eigen::Quaterniond::Identity(), p);
    return addPrior(id, prior, start);
  } catch (const std::invalid_argument& e) {
    ++stats_.priors_rejected;
    return {EdgeStatus::kRejected, "position prior on " + std::to_string(id) + ": " + e.what()};
  }
}

template <class G>
EdgeResult OnlineSmoother<G>::addFactor(const CustomFactor<G>& factor, Key id,
                                        std::optional<Key> id2) {
  std::string where = "custom factor '" + factor.name() + "' on " + std::to_string(id);
  if (id2) where += ", " + std::to_string(*id2);
  const auto reject = [&](const std::string& why) {
    ++stats_.custom_rejected;
    return EdgeResult{EdgeStatus::kRejected, where + ": " + why};
  };
  if (!factor.model) return reject("no model");
  if ((factor.arity() == 2) != id2.has_value())
    return reject("a factor on " + std::to_string(factor.arity()) + " pose(s) given " +
                  (id2 ? "2 ids" : "1 id"));
  std::array<int, 2> v{-1, -1};
  for (int k = 0; k < factor.arity(); ++k) {
    const Key key = k == 0 ? id : *id2;
    auto it = index_.find(key);
    if (it == index_.end())
      return reject("unknown pose id " + std::to_string(key) +
                    " (an edge or a prior creates a pose, a custom factor cannot)");
    v[static_cast<size_t>(k)] = it->second;
  }
  if (factor.arity() == 2 && v[0] == v[1]) return reject("self-loop");
  if (factor.arity() == 2 && root(v[0]) != root(v[1]))
    return reject("its poses are in two components; an edge must join them first");
  CustomFactor<G> f = factor;
  f.i = v[0];
  f.j = v[1];
  const Factor<G> wrapped(f);
  // Its gauge information at the current estimates, keyed 0 (and 1) on a copy of two poses:
  // the factor's functions run here, before anything changes (an exception leaves it out).
  CustomFactor<G> local = f;
  local.i = 0;
  local.j = f.j < 0 ? -1 : 1;
  std::vector<G> at{smoother_.estimate(v[0])};
  if (f.j >= 0) at.push_back(smoother_.estimate(v[1]));
  GaugeInformation<G> gauge;
  gauge.addCustom(local, at);
  try {
    smoother_.addFactor(wrapped);  // validates what a hand-assembled factor may lack
  } catch (const std::invalid_argument& e) {
    return reject(e.what());
  }
  queued_.push_back(wrapped);
  const int c = root(v[0]);
  components_[c].gauge.add(gauge);
  const bool anchored = components_[c].anchor >= 0;
  releaseAnchorIfFixed(c);
  queued_custom_.push_back(
      {queued_.size() - 1, v[0], gauge, anchored && components_[root(v[0])].anchor < 0});
  ++stats_.custom_accepted;
  return EdgeResult{EdgeStatus::kAccepted, ""};
}

template <class G>
int OnlineSmoother<G>::componentOf(Key id) const {
  auto it = index_.find(id);
  if (it == index_.end())
    throw std::out_of_range("OnlineSmoother::componentOf: unknown pose id " + std::to_string(id));
  return root(it->second);
}

template <class G>
std::optional<Key> OnlineSmoother<G>::anchorOf(Key id) const {
  const int a = components_[componentOf(id)].anchor;
  if (a < 0) return std::nullopt;
  return ids_[a];
}

template <class G>
UpdateStats OnlineSmoother<G>::update() {
  try {
    return updateOrThrow();
  } catch (const FactorError& e) {
    const std::string account = dropFailedFactor(e.factor());
    throw FactorError(account + ": " + e.what(), e.factor());
  }
}

template <class G>
std::string OnlineSmoother<G>::dropFailedFactor(int factor) {
  const int added = smoother_.numFactors();
  const auto idsOf = [&](const Factor<G>& f) {
    std::string s = "'" + f.name() + "' on pose id" + (f.arity() > 1 ? "s " : " ");
    for (int k = 0; k < f.arity(); ++k) s += (k ? ", " : "") + std::to_string(ids_[f.key(k)]);
    return s;
  };
  if (factor < added)
    return "OnlineSmoother::update: nothing applied; " +
           idsOf(smoother_.factors()[static_cast<size_t>(factor)]) +
           " is in the graph (it failed relinearised) and stays";
  const size_t k = static_cast<size_t>(factor - added);
  if (k >= queued_.size()) return "OnlineSmoother::update: nothing applied";
  const std::string what = idsOf(queued_[k]);
  auto it = std::find_if(queued_custom_.begin(), queued_custom_.end(),
                         [&](const QueuedCustom& q) { return q.position == k; });
  if (it == queued_custom_.end() || it->released_anchor)
    return "OnlineSmoother::update: nothing applied; " + what +
           " stays queued (its gauge information released its component's anchor)";
  smoother_.discardQueuedFactor(factor);
  queued_.erase(queued_.begin() + static_cast<std::ptrdiff_t>(k));
  components_[root(it->pose)].gauge.remove(it->gauge);
  it = queued_custom_.erase(it);
  for (; it != queued_custom_.end(); ++it) --it->position;
  --stats_.custom_accepted;
  ++stats_.custom_rejected;
  return "OnlineSmoother::update: nothing applied; " + what + " taken out of the queue";
}

template <class G>
UpdateStats OnlineSmoother<G>::updateOrThrow() {
  if (!gnc_) return recordUpdate(smoother_.update());
  // The online GNC (bayestree/online_gnc.*) never reweights a disabled edge: the factors of a
  // pair taken back are excluded from it (disableEdge, and excludeDisabled for those that
  // enter while their pair is disabled).
  const size_t held = gnc_->held();
  // The first graduation step rides on this update.
  gnc_->step(smoother_, recheck_all_ ? StepScope::kAll : StepScope::kRoundRobin);
  recheck_all_ = false;
  int first = smoother_.numFactors();
  UpdateStats total = smoother_.update();
  gnc_->resolve(smoother_);
  excludeDisabled(first);
  // The warm-up's end: the held closures just entered together, and one Gauss–Newton step from
  // the odometry chain leaves the estimate short of them wherever a lap's rotation drift is
  // large. The closures judged next would be judged, and σ̂² fed, on that transient;
  // relinearizeAll (Gauss–Newton over every variable), once in the run, takes the estimate to
  // them first.
  if (gnc_->held() < held) {
    addStats(&total, smoother_.relinearizeAll());
    ++stats_.warm_up_relinearizations;
  }
  for (int k = 1; k < gnc_->options().steps_per_update && gnc_->graduating(); ++k) {
    gnc_->step(smoother_);
    first = smoother_.numFactors();
    addStats(&total, smoother_.update());
    gnc_->resolve(smoother_);
    excludeDisabled(first);
    ++stats_.graduation_updates;
  }
  // The end's scale on the way (robust_constants::kEndScaleGrowth): its drops in an update of
  // their own, as finalize()'s are taken in by its next relinearisation.
  if (gnc_->readEndScaleOnTheWay(smoother_, total.reelimination_flops) > 0) {
    first = smoother_.numFactors();
    addStats(&total, smoother_.update());
    gnc_->resolve(smoother_);
    excludeDisabled(first);
  }
  return recordUpdate(total);
}

template <class G>
void OnlineSmoother<G>::graduateFully(int max_updates, UpdateStats* total,
                                      const CancellationToken* cancel) {
  for (int k = 0; k < max_updates && gnc_->graduating(); ++k) {
    if (cancel != nullptr && cancel->cancelled()) {
      total->cancelled = true;
      return;
    }
    gnc_->step(smoother_);
    addStats(total, smoother_.update());
    gnc_->resolve(smoother_);
    ++stats_.graduation_updates;
  }
}

// Robust: each round graduates every closure to the end, re-checks every settled one at the
// kernel (a change graduates it again), and another round runs only while the re-check changed
// a weight; every round after the first relinearises all before its re-check, and the last one
// ends relinearised.
template <class G>
UpdateStats OnlineSmoother<G>::finalize(const CancellationToken* cancel) {
  if (!gnc_) {
    const UpdateStats s = recordUpdate(smoother_.relinearizeAll(cancel));
    if (!s.cancelled) finalized_update_ = stats_.updates;
    return s;
  }
  UpdateStats total;
  // Closures still held in the warm-up (σ̂² never came: too few corroborated, too few judged)
  // are judged one at a time in arrival order, each at the estimate the ones before it made:
  // all at once, every one would be judged on the odometry chain alone.
  // Those updates take one Gauss–Newton step each towards the closures they let in: the first
  // re-check then reads a relinearised estimate too (MIT_random_0.1: all 22 held to here).
  const bool judged_here = gnc_->held() > 0;
  for (size_t k = gnc_->held(); k > 0; --k) {
    if (gnc_->judgeHeld(smoother_, 1) == 0) continue;
    addStats(&total, smoother_.update());
    gnc_->resolve(smoother_);
  }
  const int bound = gnc_->options().max_steps_per_closure + 1;
  gnc_->beginFinalize();
  // The first round's re-check reads the replay's own estimate (not after judging held closures
  // above: those updates moved it); a round after one that changed a weight relinearises
  // everything first and reads the converged estimate, and the last round, whichever it is, ends
  // relinearised. The replay's estimate is within thousandths of the converged one in F, and
  // the re-checks find the same closures at either.
  const bool relinearize_first = judged_here;
  auto relinearizeAll = [&] {
    addStats(&total, smoother_.relinearizeAll(cancel));
    gnc_->resolve(smoother_);
  };
  for (int round = 0;; ++round) {
    graduateFully(bound, &total, cancel);
    if (total.cancelled) break;
    const bool last = round + 1 >= gnc_->options().finalize_rounds;
    const bool relinearized = round > 0 || last || relinearize_first;
    if (relinearized) relinearizeAll();
    if (total.cancelled || last) break;
    const int changed = gnc_->step(smoother_, StepScope::kFinalize);
    if (changed == 0 && !gnc_->graduating()) {
      if (!relinearized) relinearizeAll();
      break;
    }
  }
  // Kept at Ω's word (RobustRule::kEndWord; online_gnc.h): what the final estimate explains
  // within Ω's own χ² bound comes back, and the estimate is relinearised with it; again while
  // one came back.
  if (gnc_->options().on(RobustRule::kEndWord))
    for (int round = 0; round < gnc_->options().finalize_rounds && !total.cancelled; ++round) {
      if (gnc_->takeBackAtWord(smoother_) == 0) break;
      relinearizeAll();
    }
  const UpdateStats s = recordUpdate(total);
  if (!total.cancelled) finalized_update_ = stats_.updates;
  return s;
}

template <class G>
std::vector<ClosureReport> OnlineSmoother<G>::closures() const {
  if (!gnc_) return {};
  std::vector<ClosureReport> out = gnc_->closures();
  for (ClosureReport& r : out)  // the weight in the smoother (the caller's for an excluded one)
    if (r.factor >= 0) r.weight = smoother_.factors()[static_cast<size_t>(r.factor)].inlierWeight();
  return out;
}

template <class G>
UpdateStats OnlineSmoother<G>::recordUpdate(const UpdateStats& s) {
  queued_.clear();
  queued_custom_.clear();
  if (queued_.capacity() > 4096) std::vector<Factor<G>>().swap(queued_);  // a burst's queue
  poses_at_update_ = static_cast<int>(ids_.size());
  ++stats_.updates;
  stats_.total_update_time_s += s.time_s;
  stats_.last_update = s;
  indexEdgeFactors();
  return s;
}

template <class G>
PoseGraph<G> OnlineSmoother<G>::snapshot(SnapshotJudgement* judgement) const {
  PoseGraph<G> graph = snapshot();
  *judgement = {};
  const auto& fs = smoother_.factors();
  for (size_t k = 0; k < fs.size(); ++k) {  // the order snapshot() adds the edges in
    if (disabledFactor(fs[k]) || fs[k].relativePose() == nullptr) continue;
    const int f = static_cast<int>(k);
    judgement->judged.push_back(gnc_ && gnc_->judges(f) ? 1 : 0);
    judgement->kernels.push_back(gnc_ ? gnc_->kernelOf(f) : KernelKind::kNone);
    judgement->held_out.push_back(gnc_ && gnc_->judges(f) && !gnc_->settledInlier(f) ? 1 : 0);
  }
  return graph;
}

template <class G>
PoseGraph<G> OnlineSmoother<G>::snapshot() const {
  PoseGraph<G> graph;
  const int n = poses_at_update_;
  graph.ids.assign(ids_.begin(), ids_.begin() + n);
  graph.index.reserve(static_cast<size_t>(n));
  for (int k = 0; k < n; ++k) graph.index.emplace(ids_[k], k);
  graph.poses = smoother_.estimate();
  graph.poses.resize(static_cast<size_t>(n));
  for (const auto& f : smoother_.factors())  // only poses known then
    if (!disabledFactor(f)) addToGraph(f, &graph);
  for (int k = 0; k < n; ++k)
    if (smoother_.isFixed(k)) graph.fixed.push_back(k);
  graph.has_initial_estimate = true;
  return graph;
}

template <class G>
std::vector<G> OnlineSmoother<G>::completeSeed(std::vector<G> values,
                                               const std::vector<char>& given) const {
  const size_t n = ids_.size();
  const std::vector<G> current = smoother_.estimate();
  // The rigid move that puts the given value of the first pose onto its fixed one (when it is an
  // anchor); every anchor keeps its fixed value.
  const bool first_fixed = smoother_.isFixed(0);
  const G anchor =
      given[0] && first_fixed ? current[0].compose(values[0].inverse()) : G::Identity();
  if (!given[0] || first_fixed) values[0] = current[0];
  for (size_t k = 1; k < n; ++k) {
    if (smoother_.isFixed(static_cast<int>(k))) {
      values[k] = current[k];
    } else if (given[k]) {
      values[k] = anchor.compose(values[k]);
    } else if (creator_[k] < 0) {  // a component's first pose (not fixed: prior-anchored)
      values[k] = current[k];
    } else {  // creators come first in dense order
      const int c = creator_[k];
      values[k] = values[c].compose(current[c].inverse().compose(current[k]));
    }
  }
  return values;
}

template <class G>
std::vector<G> OnlineSmoother<G>::seedPoint(const std::map<Key, G>& values) const {
  std::vector<G> dense(ids_.size());
  std::vector<char> given(ids_.size(), 0);
  for (const auto& [id, value] : values) {
    auto it = index_.find(id);
    if (it == index_.end()) {
      throw std::invalid_argument("OnlineSmoother::reseed: unknown pose id " + std::to_string(id));
    }
    if (!allFinite(value)) {
      throw std::invalid_argument("OnlineSmoother::reseed: the value of pose id " +
                                  std::to_string(id) + " is not finite");
    }
    dense[it->second] = value;
    given[it->second] = 1;
  }
  if (ids_.empty()) return dense;
  return completeSeed(std::move(dense), given);
}

template <class G>
std::vector<G> OnlineSmoother<G>::seedPoint(const std::vector<G>& prefix) const {
  if (prefix.size() > ids_.size()) {
    throw std::invalid_argument("OnlineSmoother::reseed: " + std::to_string(prefix.size()) +
                                " values for " + std::to_string(ids_.size()) + " known poses");
  }
  std::vector<G> dense(ids_.size());
  std::vector<char> given(ids_.size(), 0);
  for (size_t k = 0; k < prefix.size(); ++k) {
    if (!allFinite(prefix[k])) {
      throw std::invalid_argument("OnlineSmoother::reseed: the value of pose id " +
                                  std::to_string(ids_[k]) + " is not finite");
    }
    dense[k] = prefix[k];
    given[k] = 1;
  }
  if (ids_.empty()) return dense;
  return completeSeed(std::move(dense), given);
}

template <class G>
ReseedResult OnlineSmoother<G>::rebuild(const std::vector<G>& seed, bool only_if_lower) {
  ReseedResult result;
  if (ids_.empty()) return result;
  const auto t0 = std::chrono::steady_clock::now();
  IncrementalSmoother<G> fresh(options_.smoother);
  for (size_t k = 0; k < seed.size(); ++k) {
    if (smoother_.isFixed(static_cast<int>(k)))
      fresh.addFixedPose(seed[k]);
    else
      fresh.addPose(seed[k]);
  }
  for (const auto& f : smoother_.factors()) fresh.addFactor(f);
  for (const auto& f : queued_) fresh.addFactor(f);
  result.stats = fresh.update();
  result.F_rebuilt = fresh.objective();
  result.F_before = smoother_.objective();
  if (!queued_.empty()) {  // the queued factors count too, at the current estimate
    const std::vector<G> current = smoother_.estimate();
    for (const auto& f : queued_) result.F_before += f.cost(current);
  }
  if (!disabled_pairs_.empty()) {  // F over what is solved: the disabled edges left out
    const std::vector<G> current = smoother_.estimate();
    result.F_rebuilt = enabledCost(fresh.estimate(), fresh.factors());
    result.F_before = enabledCost(current, smoother_.factors()) + enabledCost(current, queued_);
  }
  if (gnc_) {  // robust: Σρ, which a seed that drops a false closure lowers (F would rise)
    // The rebuild numbers its factors anew (remap below); the GNC knows the old numbers, so
    // both points are costed with the old factors (the same ones, the same dense poses).
    const std::vector<G> current = smoother_.estimate(), rebuilt = fresh.estimate();
    result.F_rebuilt = robustCost(rebuilt, smoother_.factors()) + enabledCost(rebuilt, queued_);
    result.F_before = robustCost(current, smoother_.factors()) + enabledCost(current, queued_);
  }
  result.applied = !only_if_lower || result.F_rebuilt < result.F_before;
  if (result.applied) {
    smoother_ = std::move(fresh);
    queued_.clear();
    queued_custom_.clear();
    poses_at_update_ = static_cast<int>(ids_.size());
    pair_factors_.clear();  // the rebuild numbers the factors anew
    factors_indexed_ = 0;
    indexEdgeFactors();
    if (gnc_) {
      gnc_->remap(smoother_);  // the weights came along on the factors
      recheck_all_ = true;     // the settled closures are re-checked at the new point
    }
  }
  result.stats.time_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (result.applied) {
    ++stats_.reseeds;
    stats_.total_reseed_time_s += result.stats.time_s;
  }
  return result;
}

template <class G>
ReseedResult OnlineSmoother<G>::reseed(const std::map<Key, G>& values, bool only_if_lower) {
  return rebuild(seedPoint(values), only_if_lower);
}

template <class G>
ReseedResult OnlineSmoother<G>::reseed(const std::vector<G>& prefix, bool only_if_lower) {
  return rebuild(seedPoint(prefix), only_if_lower);
}

template <class G>
bool OnlineSmoother<G>::hasPose(Key id) const {
  return index_.count(id) > 0;
}

template <class G>
G OnlineSmoother<G>::estimate(Key id) const {
  auto it = index_.find(id);
  if (it == index_.end())
    throw std::out_of_range("OnlineSmoother::estimate: unknown pose id " + std::to_string(id));
  return smoother_.estimate(it->second);
}

template <class G>
std::map<Key, G> OnlineSmoother<G>::estimates() const {
  std::map<Key, G> out;
  const std::vector<G> all = smoother_.estimate();
  for (size_t k = 0; k < ids_.size(); ++k) out.emplace(ids_[k], all[k]);
  return out;
}

template <class G>
OnlineStats OnlineSmoother<G>::stats() const {
  OnlineStats s = stats_;
  s.pairs_disabled = static_cast<int>(disabled_pairs_.size());
  for (const IdPair& p : disabled_pairs_) s.edges_disabled += edgesBetween(p);
  if (gnc_) {
    const ClosureCounts c = gnc_->counts();
    s.closures_inlier = c.inlier;
    s.closures_outlier = c.outlier;
    s.closures_trusted = c.trusted;
    s.closures_excluded = c.excluded;
    s.closures_graduating = c.graduating;
    s.graduation_steps = c.graduation_steps;
    s.closures_unconfirmed = c.unconfirmed;
    s.closures_kept_at_word = c.kept_at_word;
    s.rechecks_bounded = c.rechecks_bounded;
    s.closure_threshold = gnc_->threshold();
    s.closure_threshold_at_end = gnc_->thresholdAtEnd();
    s.noise_scale = gnc_->noiseScale();
    s.noise_samples = gnc_->noiseSamples();
    s.noise_scale_estimated = gnc_->noiseEstimate().estimated;
  }
  return s;
}

// Factors from `first` on that entered between a pair taken back leave the GNC.
template <class G>
void OnlineSmoother<G>::excludeDisabled(int first) {
  if (disabled_pairs_.empty()) return;
  for (int f = first; f < smoother_.numFactors(); ++f)
    if (factorDisabled(f)) {
      gnc_->exclude(smoother_, f);
      smoother_.setFactorWeight(f, 0.0);  // whatever a graduation step gave it before
    }
}

// ---- Taking an edge back ---------------------------------------------------------------------

template <class G>
int OnlineSmoother<G>::edgesBetween(const IdPair& p) const {
  if (p.first == p.second) return 0;  // no self-loops are accepted
  int n = 0;
  for (const auto& key : {p, IdPair{p.second, p.first}}) {
    auto it = seen_.find(key);
    if (it != seen_.end()) n += static_cast<int>(it->second.size());
  }
  return n;
}

template <class G>
std::optional<EdgeSwitchResult> OnlineSmoother<G>::switchProblem(Key from, Key to,
                                                                 const char* what) const {
  const std::string edge =
      std::string(what) + " edge " + std::to_string(from) + " - " + std::to_string(to) + ": ";
  for (Key id : {from, to})
    if (!hasPose(id))
      return EdgeSwitchResult{EdgeSwitchStatus::kUnknownPose, 0,
                              edge + "unknown pose id " + std::to_string(id)};
  if (from == to || edgesBetween(idPair(from, to)) == 0)
    return EdgeSwitchResult{EdgeSwitchStatus::kNoSuchEdge, 0,
                            edge + "no accepted edge between these poses"};
  return std::nullopt;
}

// Whether the two poses of p stay connected by the enabled edges without p's: a breadth-first
// search from one to the other over every accepted edge of another pair not disabled, O(n + m).
template <class G>
bool OnlineSmoother<G>::connectedWithout(const IdPair& p) const {
  std::vector<std::vector<int>> adjacent(ids_.size());
  for (const auto& [key, measurements] : seen_) {
    const IdPair q = idPair(key.first, key.second);
    if (measurements.empty() || q == p || disabled_pairs_.count(q)) continue;
    const int a = index_.at(key.first), b = index_.at(key.second);
    adjacent[a].push_back(b);
    adjacent[b].push_back(a);
  }
  const int source = index_.at(p.first), target = index_.at(p.second);
  std::vector<char> seen(ids_.size(), 0);
  std::vector<int> frontier = {source};
  seen[source] = 1;
  while (!frontier.empty()) {
    const int v = frontier.back();
    frontier.pop_back();
    if (v == target) return true;
    for (int w : adjacent[v])
      if (!seen[w]) {
        seen[w] = 1;
        frontier.push_back(w);
      }
  }
  return false;
}

template <class G>
void OnlineSmoother<G>::setPairWeight(const IdPair& p, double w) {
  auto it = pair_factors_.find(p);
  if (it != pair_factors_.end())
    for (int f : it->second) smoother_.setFactorWeight(f, w);
  const int added = smoother_.numFactors();  // queued_ mirrors the smoother's queue
  for (size_t k = 0; k < queued_.size(); ++k) {
    const auto* e = queued_[k].relativePose();
    if (e == nullptr || idPair(ids_[e->i], ids_[e->j]) != p) continue;
    smoother_.setFactorWeight(added + static_cast<int>(k), w);
    queued_[k].setInlierWeight(w);
  }
}

template <class G>
void OnlineSmoother<G>::indexEdgeFactors() {
  const std::vector<Factor<G>>& fs = smoother_.factors();
  for (int f = factors_indexed_; f < static_cast<int>(fs.size()); ++f)
    if (const auto* e = fs[f].relativePose())
      pair_factors_[idPair(ids_[e->i], ids_[e->j])].push_back(f);
  factors_indexed_ = static_cast<int>(fs.size());
}

template <class G>
bool OnlineSmoother<G>::disabledFactor(const Factor<G>& f) const {
  if (disabled_pairs_.empty()) return false;
  const auto* e = f.relativePose();
  return e != nullptr && disabled_pairs_.count(idPair(ids_[e->i], ids_[e->j])) > 0;
}

template <class G>
bool OnlineSmoother<G>::factorDisabled(int index) const {
  const std::vector<Factor<G>>& fs = smoother_.factors();
  return index >= 0 && index < static_cast<int>(fs.size()) && disabledFactor(fs[index]);
}

template <class G>
double OnlineSmoother<G>::enabledCost(const std::vector<G>& x,
                                      const std::vector<Factor<G>>& fs) const {
  double F = 0;
  for (const Factor<G>& f : fs)
    if (!disabledFactor(f)) F += f.cost(x);
  return F;
}

template <class G>
double OnlineSmoother<G>::robustCost(const std::vector<G>& x,
                                     const std::vector<Factor<G>>& fs) const {
  // Σρ = Σ_judged ρ_c(s) + Σ_others s, s = eᵀΩe at x; the disabled edges left out.
  double F = 0;
  for (size_t k = 0; k < fs.size(); ++k) {
    if (disabledFactor(fs[k])) continue;
    const double cost = fs[k].cost(x);
    F += gnc_ ? gnc_->rho(static_cast<int>(k), cost) : cost;
  }
  return F;
}

template <class G>
double OnlineSmoother<G>::robustObjective() const {
  return robustCost(smoother_.estimate(), smoother_.factors());
}

template <class G>
double OnlineSmoother<G>::objective() const {
  if (disabled_pairs_.empty()) return smoother_.objective();
  return enabledCost(smoother_.estimate(), smoother_.factors());
}

namespace {

/// "edge FROM - TO (N accepted edges)": how the results of disableEdge/enableEdge name a pair.
std::string pairText(Key from, Key to, int n) {
  return "edge " + std::to_string(from) + " - " + std::to_string(to) + " (" + std::to_string(n) +
         (n == 1 ? " accepted edge)" : " accepted edges)");
}

}  // namespace

template <class G>
EdgeSwitchResult OnlineSmoother<G>::disableEdge(Key from, Key to) {
  if (auto refusal = switchProblem(from, to, "disable")) return *refusal;
  const IdPair p = idPair(from, to);
  const int n = edgesBetween(p);
  const std::string edge = pairText(from, to, n);
  if (disabled_pairs_.count(p))
    return {EdgeSwitchStatus::kAlreadyDisabled, n, "disable " + edge + ": disabled already"};
  if (!connectedWithout(p)) {
    return {EdgeSwitchStatus::kBridge, n,
            "disable " + edge + ": refused, a bridge: without it poses " + std::to_string(from) +
                " and " + std::to_string(to) +
                " are not connected by enabled edges and one side would lose its gauge"};
  }
  disabled_pairs_.insert(p);
  setPairWeight(p, 0.0);
  if (gnc_) {  // the GNC leaves them alone until enableEdge
    auto it = pair_factors_.find(p);
    if (it != pair_factors_.end())
      for (int f : it->second) {
        gnc_->exclude(smoother_, f);
        smoother_.setFactorWeight(f, 0.0);
      }
  }
  return {EdgeSwitchStatus::kApplied, n, "disabled " + edge + " from the next update on"};
}

template <class G>
EdgeSwitchResult OnlineSmoother<G>::enableEdge(Key from, Key to) {
  if (auto refusal = switchProblem(from, to, "enable")) return *refusal;
  const IdPair p = idPair(from, to);
  const int n = edgesBetween(p);
  const std::string edge = pairText(from, to, n);
  if (!disabled_pairs_.count(p))
    return {EdgeSwitchStatus::kAlreadyEnabled, n, "enable " + edge + ": not disabled"};
  disabled_pairs_.erase(p);
  setPairWeight(p, 1.0);
  if (gnc_) {  // a loop closure goes through the GNC's first check again (include)
    auto it = pair_factors_.find(p);
    if (it != pair_factors_.end())
      for (int f : it->second) gnc_->include(smoother_, f);
  }
  return {EdgeSwitchStatus::kApplied, n, "enabled " + edge + " from the next update on"};
}

template <class G>
typename OnlineSmoother<G>::Matrix OnlineSmoother<G>::marginalCovariance(Key id) const {
  return jointMarginalCovariance(id, id).template topLeftCorner<kDoF, kDoF>();
}

template <class G>
auto OnlineSmoother<G>::jointMarginalCovariance(Key a, Key b) const
    -> Eigen::Matrix<double, 2 * kDoF, 2 * kDoF> {
  int index[2];
  for (int k = 0; k < 2; ++k) {
    const Key id = k == 0 ? a : b;
    auto it = index_.find(id);
    if (it == index_.end())
      throw std::out_of_range("OnlineSmoother: covariance of unknown pose id " +
                              std::to_string(id));
    index[k] = it->second;
    try {  // its own marginal first (cached: the joint below reuses it) names the pose
      smoother_.marginalCovariance(index[k]);
    } catch (const std::logic_error&) {
      throw std::logic_error("OnlineSmoother: covariance of pose id " + std::to_string(id) +
                             ": not in the Bayes tree yet (call update() first)");
    }
  }
  return smoother_.jointMarginalCovariance(index[0], index[1]);
}

template class OnlineSmoother<SE2>;
template class OnlineSmoother<SE3>;

}  // namespace arbor
