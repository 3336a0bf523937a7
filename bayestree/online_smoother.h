// The online layer over IncrementalSmoother: poses named by external ids (Key), edges and priors
// arriving one at a time in any order. An edge to an unknown pose creates it from the known end
// composed with the measurement (or its inverse).
//
// Components (docs/design.md, "Gauge and components"): poses linked by edges form components,
// each estimated from its first factor on. A component is anchored at its first pose, held
// fixed, unless its priors fix its gauge (core/gauge.h); then nothing in it is fixed. An edge
// between two unknown poses starts a new component (a second robot, a second session). When an
// edge joins two components, the one whose priors fix its gauge — else the older — keeps its
// frame; the other moves rigidly into that frame through the joining edge in the same update
// (IncrementalSmoother::transformPoses: its relative-pose factors and Δ are unchanged by the
// move) and its anchor is released. When priors come to fix a component's gauge, its anchor is
// released.
//
// Taking an edge back (disableEdge / enableEdge; docs/design.md, "Taking an edge back"): every
// accepted edge between two ids gets smoother weight 0 (IncrementalSmoother::setFactorWeight),
// sticky until enableEdge restores weight 1; an edge between them accepted meanwhile enters
// disabled too. A disable that would split a component (its edges are a bridge of the graph of
// enabled edges) is refused, so every component stays connected by enabled edges and keeps its
// gauge.
//
// Reseeding (reseed()) makes given values — typically a batch solver's estimate of a snapshot()
// — the linearisation point and rebuilds the Bayes tree from scratch; incremental updates then
// continue from there. With robust smoothing the closures keep their weights, a rebuild is kept
// (only_if_lower) when it lowers Σρ, and the next update re-checks every settled closure at the
// new point (OnlineGnc::step with recheck_all): the classification a robust batch found comes
// in through the values it gives.
//
// Robust smoothing (OnlineSmootherOptions::robust, off by default): every loop closure is judged
// and graduated by an OnlineGnc (bayestree/online_gnc.h) through the smoother's weight seam;
// odometry, edges marked EdgeTrust::kTrusted, edges that create a pose or join two components,
// and priors are trusted. Without it nothing changes, bit for bit.
//
// Thread-safety: none. One thread owns an OnlineSmoother and makes every call (the LCM service
// feeds it from its single handler thread); const methods may run concurrently only with other
// const methods.
#pragma once

#include <algorithm>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>

#include "arbor_slam/bayestree/incremental_smoother.h"
#include "arbor_slam/bayestree/online_gnc.h"
#include "arbor_slam/core/factor.h"
#include "arbor_slam/core/gauge.h"
#include "arbor_slam/core/pose_graph.h"

namespace arbor {

enum class EdgeStatus {
  kAccepted,   ///< added (to be used by the next update())
  kDuplicate,  ///< same ids, measurement and Ω as an accepted edge: not added again
  kPending,    ///< not produced any more: an edge between unknown poses starts a component
  kRejected,   ///< bad input; see reason
};

const char* toString(EdgeStatus status);

struct EdgeResult {
  EdgeStatus status = EdgeStatus::kAccepted;
  std::string reason;  ///< why it was rejected (or which edge it duplicates)
};

/// What disableEdge / enableEdge did.
enum class EdgeSwitchStatus {
  kApplied,          ///< done: the next update() applies the new weights
  kUnknownPose,      ///< an id is not a known pose: nothing changed
  kNoSuchEdge,       ///< no accepted edge between the two ids: nothing changed
  kAlreadyDisabled,  ///< disableEdge of a pair disabled already: nothing changed
  kAlreadyEnabled,   ///< enableEdge of a pair not disabled: nothing changed
  kBridge,           ///< disableEdge refused: without these edges a component falls apart
};

const char* toString(EdgeSwitchStatus status);

struct EdgeSwitchResult {
  EdgeSwitchStatus status = EdgeSwitchStatus::kApplied;
  int edges = 0;       ///< accepted edges between the two ids (either direction)
  std::string reason;  ///< what happened, or why not, naming the ids
  bool applied() const { return status == EdgeSwitchStatus::kApplied; }
};

template <class G>
struct OnlineSmootherOptions {
  SmootherOptions smoother;
  G gauge = G::Identity();  ///< the value of the first pose seen (held fixed)
  /// Online robust smoothing of the loop closures (bayestree/online_gnc.h); none: off.
  std::optional<RobustOptions> robust;
};

/// What reseed() did.
struct ReseedResult {
  bool applied = false;  ///< the rebuilt smoother replaced the old one
  /// F over every factor at the estimate before / at the rebuilt estimate; with robust
  /// smoothing Σρ (robustObjective) instead, what only_if_lower compares.
  double F_before = 0;
  double F_rebuilt = 0;
  UpdateStats stats;  ///< of the rebuild's update; time_s: the whole rebuild
};

struct OnlineStats {
  int poses = 0;
  int edges_accepted = 0;  ///< edges handed to the smoother
  int edges_duplicate = 0;
  int edges_pending = 0;  ///< always 0 (kept for the status message's layout)
  int edges_rejected = 0;
  int priors_accepted = 0;  ///< pose and position priors handed to the smoother
  int priors_rejected = 0;
  int custom_accepted = 0;  ///< factors of your own handed to the smoother (addFactor)
  int custom_rejected = 0;
  int components = 0;  ///< connected components now
  int joins = 0;       ///< edges that joined two components
  int anchors_released = 0;
  int updates = 0;
  double total_update_time_s = 0;
  int reseeds = 0;  ///< rebuilds by reseed() that were kept
  double total_reseed_time_s = 0;
  int edges_disabled = 0;  ///< accepted edges disabled now (disableEdge), weight 0
  int pairs_disabled = 0;  ///< id pairs disabled now
  UpdateStats last_update;
  // With OnlineSmootherOptions::robust (else 0): loop closures (|from − to| ≠ 1) by status
  // (ClosureStatus), those of inlier + outlier still graduating, the weight changes made by
  // graduation, and the extra smoother updates graduation ran (steps_per_update > 1, finalize).
  int closures_inlier = 0;
  int closures_outlier = 0;
  int closures_trusted = 0;
  int closures_excluded = 0;
  int closures_graduating = 0;
  int graduation_steps = 0;
  int graduation_updates = 0;
  /// Inliers dropped by their leave-one-out innovation (ClosureCounts::unconfirmed).
  int closures_unconfirmed = 0;
  /// Rejected closures taken back at the end by their residual within Ω's χ² bound
  /// (ClosureCounts::kept_at_word; RobustRule::kEndWord).
  int closures_kept_at_word = 0;
  /// Re-checks of rejected closures that (E)'s lower bound settled without a path solve
  /// (ClosureCounts::rechecks_bounded).
  int rechecks_bounded = 0;
  /// Relinearisations of everything at the warm-up's end (OnlineSmoother::update): one in a
  /// run whose σ̂² came while closures were held, else 0.
  int warm_up_relinearizations = 0;
  /// With robust smoothing: c² in use (OnlineGnc::threshold), σ̂² (OnlineGnc::noiseScale,
  /// 1 without robust smoothing) and the innovations it is estimated from.
  double closure_threshold = 0;
  /// The c² finalize()'s last leave-one-out pass judged by (OnlineGnc::thresholdAtEnd: the
  /// end's scale where it is at least end_scale_gap times tighter, else closure_threshold);
  /// 0 before such a pass.
  double closure_threshold_at_end = 0;
  double noise_scale = 1;
  int noise_samples = 0;
  /// σ̂² is an estimate (NoiseScaleEstimate::estimated); false: Ω at its word.
  bool noise_scale_estimated = false;
};

/// Per edge of an OnlineSmoother::snapshot(), in its order: how the online GNC holds it.
struct SnapshotJudgement {
  std::vector<char> judged;         ///< weighted by the online GNC (the others are trusted)
  std::vector<KernelKind> kernels;  ///< the kernel it is judged by (OnlineGnc::kernelOf; kNone)
  /// a closure the online GNC judges and does not hold as a settled inlier now: rejected, or
  /// undecided (graduating, held in the warm-up); OnlineGnc::settledInlier
  std::vector<char> held_out;
};

template <class G>
class OnlineSmoother {
 public:
  static constexpr int kDoF = G::kDoF;
  static constexpr int kDim = G::kDim;
  using Matrix = Eigen::Matrix<double, kDoF, kDoF>;
  using PositionMatrix = Eigen::Matrix<double, kDim, kDim>;

  explicit OnlineSmoother(OnlineSmootherOptions<G> options = {});

  /// One measurement z of pose `to` in the frame of pose `from`, with information Ω. With
  /// robust smoothing, `trust` kTrusted keeps a loop closure out of the GNC (weight 1 for good),
  /// kRobust judges an edge even between consecutive ids; `kernel` is the kernel this edge is
  /// judged by (kNone: RobustOptions::kernel). Both are ignored without robust smoothing.
  EdgeResult addEdge(Key from, Key to, const G& z, const Matrix& omega,
                     EdgeTrust trust = EdgeTrust::kByRule, KernelKind kernel = KernelKind::kNone);
  /// A prior z on pose `id` in the world frame (core/prior_factors.h), with an optional sensor
  /// offset o (the prior is on x o). An unknown id starts a component there, at z o⁻¹.
  EdgeResult addPosePrior(Key id, const G& z, const Matrix& omega, const G& offset = G::Identity());
  /// A prior p on the position of pose `id` in the world frame (GPS in a local frame). An
  /// unknown id starts a component there (at p, identity rotation).
  EdgeResult addPositionPrior(Key id, const typename G::Translation& p,
                              const PositionMatrix& omega);
  /// A factor of your own (core/custom_factor.h; its keys are replaced) on pose `id`, or on
  /// `id` and `id2` for a binary one. The poses must exist (nothing places a new pose from a
  /// custom factor) and a binary one's be in one component (an edge joins components). Its
  /// gauge information joins its component's (core/gauge.h): when that fixes the gauge, the
  /// anchor is released (the estimate stays where the anchor held it: give initial guesses in
  /// the factors' frame). Trusted by robust smoothing (weight 1). Refused with the reason
  /// otherwise, changing nothing.
  EdgeResult addFactor(const CustomFactor<G>& factor, Key id,
                       std::optional<Key> id2 = std::nullopt);
  /// The value pose `id` starts at when an edge creates it, instead of the estimate of the pose
  /// the edge comes from composed with the measurement (iSAM2's new Θ of ISAM2::update): a map
  /// saved at its optimum, or a front end's own odometry, starts near its optimum, and the first
  /// relinearisation checks then mark few variables. In the frame of the estimate (that of the
  /// component's first pose, where a new component also starts at its guess); a component
  /// moved onto another by a join keeps its relative placement, not its guesses'. Used once, by
  /// the edge that creates the pose (a pose created already ignores it). Returns false, and
  /// keeps nothing, when the value is not finite or the pose exists.
  bool setInitialGuess(Key id, const G& value);
  /// Takes back every accepted edge between `from` and `to` (either direction): smoother weight
  /// 0 from the next update() on, until enableEdge; an edge between them accepted meanwhile
  /// enters disabled. Refused, changing nothing, for an unknown id, no edge between them, a pair
  /// disabled already, and a bridge: when the two would not be connected by the enabled edges
  /// left (a breadth-first search, O(n + m)), the component would fall apart and one part lose
  /// its gauge.
  EdgeSwitchResult disableEdge(Key from, Key to);
  /// Gives the edges between `from` and `to` weight 1 again from the next update() on. Refused,
  /// changing nothing, for an unknown id, no edge between them, or a pair not disabled.
  EdgeSwitchResult enableEdge(Key from, Key to);
  /// Whether factor `index` of smoother().factors() is an edge taken back by disableEdge. A
  /// robust layer (online GNC) must leave such a factor at weight 0.
  bool factorDisabled(int index) const;
  /// F = Σ eᵀΩe at the estimate over every factor not disabled (= smoother().objective() while
  /// no edge is disabled). O(m).
  double objective() const;

  /// Runs one incremental update over the edges accepted since the last one. With robust
  /// smoothing, first one graduation step (OnlineGnc::step), then up to steps_per_update − 1
  /// more, each a smoother update of its own (summed into the stats returned).
  ///
  /// When a factor of your own fails in it (IncrementalSmoother::update: FactorError), the
  /// update applies nothing and throws FactorError naming the factor by its pose ids; a queued
  /// factor that failed is taken out of the queue (rejected: OnlineStats::custom_rejected), so
  /// the next update() applies the rest, as if it had never been added. Not taken out, and
  /// said so in the message: a factor in the graph already (it failed relinearised), or one
  /// whose gauge information released its component's anchor. With robust smoothing the
  /// graduation step taken before the failure stays (its weights wait for the next update).
  UpdateStats update();
  /// Relinearises everything and iterates to convergence (the end of a replay). With robust
  /// smoothing, first graduates every closure to the end (bounded by max_steps_per_closure
  /// updates) and re-checks every settled one, up to RobustOptions::finalize_rounds rounds.
  /// With a token: checked before each relinearise-all iteration and each graduation update
  /// (one cancelled() call each, in a fixed order), and everything stops once it is cancelled;
  /// the estimate is then that of the last step completed (UpdateStats::cancelled). The same
  /// count of passed checks (CancellationToken::cancelAfterChecks) repeats the cut exactly.
  UpdateStats finalize(const CancellationToken* cancel = nullptr);
  /// finalize() ran to its end (not cancelled), was the last update, and nothing was added
  /// since: the online GNC's classification is its final one (a robust batch then starts from
  /// it, tools/refine/gnc_from_online.h).
  bool finalized() const { return finalized_update_ == stats_.updates && queued_.empty(); }
  /// SmootherOptions::solve_budget_mb: solves the cliques the budget deferred, all of them or
  /// about `budget_mb` of them (IncrementalSmoother::solveDeferred); adds nothing queued.
  UpdateStats solveDeferred(double budget_mb = 0) { return smoother_.solveDeferred(budget_mb); }
  /// With robust smoothing: every loop closure's weight and status (empty without it).
  std::vector<ClosureReport> closures() const;
  /// The robust layer, or nullptr without robust smoothing (exclude/include a factor).
  const OnlineGnc<G>* gnc() const { return gnc_ ? &*gnc_ : nullptr; }

  /// The poses known at the last update() (the first ones in dense order; the anchors listed in
  /// `fixed`), every edge and prior taken in by the smoother so far but the disabled edges, and
  /// the current estimate as `poses`: a problem for a batch solver with the same gauge (ids in
  /// dense order, not sorted).
  PoseGraph<G> snapshot() const;
  /// As snapshot(), and per snapshot edge how the online GNC holds it (*judgement; without
  /// robust smoothing nothing is judged): the edges a robust batch weights and their kernels, so
  /// that it weights each edge as the online GNC does, and the closures it does not hold as settled
  /// inliers now.
  PoseGraph<G> snapshot(SnapshotJudgement* judgement) const;
  /// The robust cost Σρ at the estimate over every factor not disabled: ρ of a judged closure
  /// at its kernel (TLS: min(s, c²)), s = eᵀΩe of everything else (= objective() without robust
  /// smoothing). O(m).
  double robustObjective() const;

  /// The complete linearisation point reseed(values) would use, in dense order:
  /// - poses in `values` take those values, all moved by the one rigid transform that puts the
  ///   gauge pose's value onto its current (fixed) value when the gauge is in `values` (else
  ///   they are taken as they are);
  /// - any other pose keeps its current estimate relative to the pose it was created from
  ///   (x_k = x'_c · x_c⁻¹ · x_k, creators first), so poses that arrived after a snapshot move
  ///   rigidly with their creator instead of being dead-reckoned again.
  /// Throws std::invalid_argument naming the id for an unknown pose or a non-finite value.
  std::vector<G> seedPoint(const std::map<Key, G>& values) const;
  /// As above with the values of the first `prefix.size()` poses in dense order (as snapshot()
  /// lists them); throws std::invalid_argument if there are more than the known poses.
  std::vector<G> seedPoint(const std::vector<G>& prefix) const;
  /// Rebuilds the smoother with seedPoint(values) as its linearisation point (the gauge pose keeps
  /// its fixed value): every factor, including those accepted since the last update(), is
  /// re-added with its weight (disabled edges stay disabled) and one update eliminates the whole
  /// tree, so the estimate afterwards is one Gauss–Newton step from the seed (equal to it when
  /// the seed is the optimum). With `only_if_lower` the rebuilt smoother is kept only when its F
  /// over every factor is lower than the current one (objective(): disabled edges left out; a batch
  /// estimate of an older snapshot can be worse for the poses and edges that came since). Throws as
  /// seedPoint(); on a throw nothing changed.
  ReseedResult reseed(const std::map<Key, G>& values, bool only_if_lower = false);
  ReseedResult reseed(const std::vector<G>& prefix, bool only_if_lower = false);

  bool hasPose(Key id) const;
  /// The current estimate; throws std::out_of_range for an unknown id.
  G estimate(Key id) const;
  std::map<Key, G> estimates() const;  ///< every known pose (O(n))
  OnlineStats stats() const;
  const IncrementalSmoother<G>& smoother() const { return smoother_; }
  /// IncrementalSmoother::setSecondCoreBusy (a background batch refinement runs meanwhile).
  void setSecondCoreBusy(bool busy) { smoother_.setSecondCoreBusy(busy); }
  /// Dense smoother index → id.
  const std::vector<Key>& ids() const { return ids_; }
  /// The component of a known pose: its representative dense index (equal for poses of one
  /// component, changing when components join). Throws std::out_of_range for an unknown id.
  int componentOf(Key id) const;
  /// The anchor (held-fixed pose) of a known pose's component, or nullopt when its priors fix
  /// its gauge.
  std::optional<Key> anchorOf(Key id) const;

  /// The marginal covariance of pose `id` (IncrementalSmoother::marginalCovariance): of the
  /// tangent at its linearisation point after the last update(), relative to its component's
  /// anchor (zero for the anchor itself) or, when priors fix the component's gauge, to the
  /// priors. Throws std::out_of_range for an unknown id, std::logic_error for a pose that has not
  /// been through update() yet.
  Matrix marginalCovariance(Key id) const;
  /// The joint covariance of poses a and b, [[Σ_aa, Σ_ab], [Σ_ba, Σ_bb]] (Σ_ab = 0 between
  /// components); throws as marginalCovariance.
  Eigen::Matrix<double, 2 * kDoF, 2 * kDoF> jointMarginalCovariance(Key a, Key b) const;

 private:
  /// Bookkeeping after an update() or finalize() of the smoother.
  UpdateStats recordUpdate(const UpdateStats& s);
  struct Measurement {
    Key from, to;
    G z;
    Matrix omega;
  };
  bool sameMeasurement(const Measurement& a, const Measurement& b) const;
  /// A new pose; creator −1 starts a component (anchored at it when `anchor`).
  int createPose(Key id, const G& value, int creator, bool anchor = true);
  /// Adds m to the smoother, creating an unknown end or a new component, or joining two.
  void apply(const Measurement& m, EdgeTrust trust, KernelKind kernel);
  /// Robust smoothing: graduation steps until none graduates or `max_updates` updates.
  void graduateFully(int max_updates, UpdateStats* total,
                     const CancellationToken* cancel = nullptr);
  /// The edge from → to (dense indices, in different components) joins them.
  void join(int from, int to, const G& z);
  /// Priors of component c now fix its gauge: its anchor is released.
  void releaseAnchorIfFixed(int c);
  int root(int v) const;
  /// Hands a prior to the smoother, validated; creates the pose (a component) when unknown.
  EdgeResult addPrior(Key id, const Factor<G>& prior, const G& start);
  std::vector<G> completeSeed(std::vector<G> values, const std::vector<char>& given) const;
  ReseedResult rebuild(const std::vector<G>& seed, bool only_if_lower);
  /// Σρ (robustObjective) of `factors` at x, skipping the disabled ones; factors past the GNC's
  /// (queued ones) count s.
  double robustCost(const std::vector<G>& x, const std::vector<Factor<G>>& factors) const;
  bool recheck_all_ = false;  ///< the next update re-checks every settled closure (reseed)

  // Taking an edge back.
  using IdPair = std::pair<Key, Key>;  ///< {min, max} of two ids
  static IdPair idPair(Key a, Key b) { return {std::min(a, b), std::max(a, b)}; }
  /// Accepted edges between the two ids, either direction.
  int edgesBetween(const IdPair& p) const;
  /// The refusal of a disable/enable of (from, to) for an unknown id or no edge, if any.
  std::optional<EdgeSwitchResult> switchProblem(Key from, Key to, const char* what) const;
  /// Whether a and b (known ids) stay connected by the enabled edges other than p's (BFS).
  bool connectedWithout(const IdPair& p) const;
  /// Sets weight w on every edge factor of p, added or queued.
  void setPairWeight(const IdPair& p, double w);
  /// Lists the edge factors of smoother_.factors() from factors_indexed_ on in pair_factors_.
  void indexEdgeFactors();
  bool disabledFactor(const Factor<G>& f) const;
  /// Σ eᵀΩe at x over the factors of fs not disabled.
  double enabledCost(const std::vector<G>& x, const std::vector<Factor<G>>& fs) const;

  OnlineSmootherOptions<G> options_;
  IncrementalSmoother<G> smoother_;
  std::unordered_map<Key, int> index_;
  std::unordered_map<Key, G> guesses_;  ///< setInitialGuess, for poses not created yet
  std::vector<Key> ids_;
  std::vector<int> creator_;  ///< per dense index: the known end it was created from (−1: none)
  // Components, a union–find over dense indices (path halving; the root's entries are the
  // component's): members (merged smaller into larger), anchor (−1: none), gauge information.
  struct Component {
    std::vector<int> members;
    int first = 0;  ///< its first pose (the older component has the lower one)
    int anchor = -1;
    GaugeInformation<G> gauge;
    // Its priors, for the move into their frame when they come to fix the gauge: the pose of
    // a pose prior and the value it asks for (z o⁻¹); the poses, positions and weights
    // (kDim / tr Ω⁻¹) of its position priors.
    int pose_prior_pose = -1;
    G pose_prior_target;
    std::vector<int> position_prior_poses;
    std::vector<typename G::Translation> position_prior_values;
    std::vector<double> position_prior_weights;
  };
  /// The rigid move that takes component c's estimate into its priors' frame.
  G moveOntoPriors(const Component& c) const;
  mutable std::vector<int> component_parent_;
  std::vector<Component> components_;
  std::vector<Factor<G>> queued_;  ///< handed to the smoother since the last update
  /// The factors of your own in queued_ (its position), their gauge information and whether
  /// adding them released their component's anchor: what taking one out undoes.
  struct QueuedCustom {
    size_t position;
    int pose;
    GaugeInformation<G> gauge;
    bool released_anchor;
  };
  std::vector<QueuedCustom> queued_custom_;
  UpdateStats updateOrThrow();
  /// After a FactorError from the smoother: takes a queued factor of your own that failed out
  /// of the queue when it can; returns the message's account of it (ids, what was done).
  std::string dropFailedFactor(int factor);
  int poses_at_update_ = 0;    ///< poses known at the last update
  int finalized_update_ = -1;  ///< stats_.updates after the last finalize() (finalized())
  std::map<std::pair<Key, Key>, std::vector<Measurement>> seen_;  ///< accepted edges
  OnlineStats stats_;
  std::set<IdPair> disabled_pairs_;                  ///< pairs taken back by disableEdge
  std::map<IdPair, std::vector<int>> pair_factors_;  ///< per pair: its edges' smoother factors
  int factors_indexed_ = 0;                          ///< smoother factors in pair_factors_
  std::optional<OnlineGnc<G>> gnc_;                  ///< robust smoothing (options_.robust)
  /// Factors from `first` on whose pair is disabled leave the GNC (after its resolve()).
  void excludeDisabled(int first);
};

using OnlineSmoother2 = OnlineSmoother<SE2>;
using OnlineSmoother3 = OnlineSmoother<SE3>;

extern template class OnlineSmoother<SE2>;
extern template class OnlineSmoother<SE3>;

}  // namespace arbor
