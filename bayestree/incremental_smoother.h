// iSAM2: incremental smoothing and mapping on a Bayes tree (Kaess, Johannsson, Roberts, Ila,
// Leonard, Dellaert, "iSAM2: Incremental smoothing and mapping using the Bayes tree", IJRR 2012).
//
// Variables are the non-fixed poses (dense indices); fixed (gauge) poses are constants, so an
// edge to one is a unary factor on its other end. Linearised factors are kept in Hessian
// (information) form and every clique is eliminated by a dense Cholesky factorisation of its
// assembled Hessian: R = chol(H_ff)ᵀ, S = R⁻ᵀH_fs, d = R⁻ᵀg_f; the parent receives the Schur
// complement (H_ss − SᵀS, g_s − Sᵀd) as the clique's cached factor. An update that only adds
// factors between poses already in the tree (a loop closure) is folded in by rank updates along
// the path to the root instead of re-eliminating it (SmootherOptions::rank_updates;
// docs/design.md).
//
// Not thread-safe: one thread owns a smoother (const methods may run concurrently with each
// other, never with a non-const one). Inside an update, the smoother's own helper threads
// share the work on the tree (SmootherOptions::threads).
#pragma once

#include <memory>
#include <vector>

#include "arbor_slam/core/cancellation.h"
#include "arbor_slam/core/factor.h"
#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/core/relative_pose_factor.h"

namespace arbor {

/// When an update re-eliminates the whole graph with a fresh ordering instead of its top
/// (docs/design.md, "Never costlier than batch"). The linear system is the same either way, so
/// the estimate is too (to rounding, and to the wildfire threshold of the partial solve).
struct BatchSwitchOptions {
  /// An update whose top to re-eliminate (Alg. 4 step 1; it holds the relinearised variables'
  /// cliques too) has more than this share of the variables re-eliminates all of them, ordered
  /// afresh by CCOLAMD with the touched variables last (as GTSAM's ISAM2 re-orders in batch past
  /// 0.65 of the variables). 1: never, the default: at 0.65 the updates of eight of nine sets
  /// measured executed 0.2-19% more instructions (intel 19%, MIT 9%), the later updates paying
  /// for the fresh orderings' trees; reorder_decay bounds a decayed ordering on its own
  /// (docs/design.md, "Never costlier than batch").
  double top_share = 1.0;
  /// The tree is re-ordered (its next re-elimination is the whole graph's) when the flops of
  /// factorising it in its incremental ordering (Σ F³/3 + F²S + FS² over its cliques), or the
  /// doubles its matrices hold (Σ F(F+S) + F + S² + S), exceed this many times a fresh
  /// ordering's. The fresh ordering is computed only when the tree's flops or doubles have
  /// grown by this factor since the last comparison, so checks are amortised. 0: never.
  double reorder_decay = 2.0;
  /// iSAM2's constrained ordering puts the variables an update touches (new, or of its new
  /// factors) last, at the root, where the next update finds them; an update that touches more
  /// than this many (a burst applied at once) orders its top unconstrained instead: a front
  /// over thousands of variables forced last fills the cliques below it (measured: a
  /// 60,000-edge Manhattan burst in a few updates needed > 14 GB constrained, 1.4 GB not;
  /// docs/benchmarks.md). ≥ 1.
  int constrain_last_max = 1000;
};

/// Which cliques keep their cached factor, the Schur complement on the separator that a clique
/// passes to its parent (Kaess et al., IJRR 2012, §3: "we cache the conditional densities and
/// the corresponding marginal factors"; docs/design.md, "Cliques without a cached factor"). It
/// is what lets an update re-eliminate only the top: an orphan's cached factor stands for its
/// whole subtree. It is also most of the tree's memory: S² doubles on a separator of dimension
/// S, against F(F+S) for the conditional of F frontal dimensions (on a fresh ordering of a
/// 1,000,000-pose Manhattan world, 9.5 of 11.8 GB; docs/benchmarks.md). A clique that keeps
/// none is removed with its parent whenever the parent is (never an orphan) and re-eliminated
/// from its factors and its children's cached factors: the same linear system, so the same
/// estimate, for more work in those updates.
struct CachedFactorOptions {
  /// 0: every clique keeps its cached factor (iSAM2). r > 0: a clique keeps it only when it is
  /// at most r times its conditional, S² ≤ r·F(F+S), decided when the clique is eliminated.
  /// 4 (measured against 0, 1 and 16, docs/benchmarks.md "Cached factors kept and dropped"):
  /// on the 50,000-pose world 3.7 times less memory and a 30% shorter replay; on the shared
  /// sets totals the same or lower and 15–53% less memory (p99 0.2–0.4 ms higher on the small
  /// 2D sets); 1 drops nearly every cached factor and re-eliminates whole subtrees (1.9 times
  /// the replay of ratio 0).
  double max_ratio = 4;
  /// A top elimination drops cached factors only when the tree it makes (what is left of the
  /// tree, plus the new cliques with every cached factor) holds at least this many doubles
  /// (10⁶: 8 MB): in a small tree they cost little memory and dropping them costs
  /// re-eliminations (measured on smallGrid3D: a 12% longer replay with none kept).
  double min_tree_doubles = 1e6;
};

/// Where Alg. 5's relinearisation happens (docs/design.md, "Asynchronous relinearisation").
enum class RelinearizationMode {
  /// On the update path: a check's marked variables are relinearised and their cliques
  /// re-eliminated in that update (Kaess et al., IJRR 2012, Alg. 4).
  kInline,
  /// A check that marks at least AsyncRelinearizationOptions::min_variables takes a snapshot
  /// (the factors, Θ with Θ_M ⊕ Δ_M, the fixed poses); a background thread linearises every
  /// factor there and eliminates the whole graph in a fresh ordering, while updates go on on
  /// the old tree without relinearising; the first update after it is ready folds what arrived
  /// since the snapshot into the new tree as one ordinary pass and swaps it in. The estimate
  /// is then the one relinearising at the snapshot and applying the later updates inline gives.
  kAsync,
};

/// Where the swap folds in what arrived during the relinearisation job (docs/design.md,
/// "Asynchronous relinearisation").
enum class AsyncCatchUp {
  /// The update that finds the job done folds it into the job's tree and swaps the tree in: that
  /// update re-eliminates the fresh ordering's root (its last separator, large) on the path.
  kOnSwap,
  /// The update that finds the job done hands the job's tree, with what arrived since the
  /// snapshot, to a second background job that folds it in (an ordinary pass, on a copy of the
  /// smoother's state); the first update that finds that done swaps it in, folding in only what
  /// arrived during the catch-up, into a tree whose top is already the incremental one's.
  kInBackground,
};

/// The asynchronous mode's settings (RelinearizationMode::kAsync).
struct AsyncRelinearizationOptions {
  /// A check that marks fewer variables relinearises inline (a small top costs less than the
  /// snapshot and the whole-graph elimination).
  int min_variables = 64;
  /// The job runs on the calling thread when the snapshot is taken (deterministic; tests).
  bool synchronous = false;
  /// 0: the swap happens at the first update that finds the job done. d > 0: exactly at the
  /// d-th update after the snapshot's, which waits for the job if it is still running
  /// (deterministic whatever the scheduling; tests).
  int swap_after_updates = 0;
  /// Where the swap's fold-ins run. With swap_after_updates d > 0 the catch-up starts at the
  /// d-th update after the snapshot's and is swapped in at the next one (which waits for it).
  AsyncCatchUp catch_up = AsyncCatchUp::kInBackground;
  /// A tree whose ordering has decayed (BatchSwitchOptions::reorder_decay) is re-ordered by a
  /// job too: a snapshot at the next update, whatever its M (empty: the same linearisation
  /// point, a fresh ordering), instead of the next re-elimination being a batch one on the
  /// update path. A decay past BatchSwitchOptions::reorder_decay found while a job is wanted
  /// already, or the second core busy, re-orders inline as before. false: every re-ordering
  /// inline.
  bool reorder_in_background = true;
  /// The decay (as BatchSwitchOptions::reorder_decay; ≥ 1) at which a re-ordering job is asked
  /// for; at most the batch option's, which stays the bound past which the update path
  /// re-orders inline. A job costs the update path little, so it re-orders sooner than inline
  /// (docs/benchmarks.md, "Re-ordering sooner in the background": 1.5 against 2 lowers the
  /// largest update and the peak memory of a 50,000-pose world, the shared sets within noise).
  double reorder_decay = 1.5;
  /// The job's Gauss–Newton iterations on its snapshot (relinearizeSnapshot): 1 eliminates the
  /// graph once, at the snapshot's Θ (Θ_M ⊕ Δ_M); k > 1 steps every pose and re-eliminates up
  /// to k − 1 more times while F falls by more than SmootherOptions::finalize_relative_tolerance
  /// (as relinearizeAll does), and the swap takes the tree at the last Θ. Longer jobs, fewer of
  /// them: on sphere_bignoise 5 about halves the updates above 3 ms (docs/benchmarks.md,
  /// "Asynchronous relinearisation").
  int job_iterations = 1;
  /// AsyncCatchUp::kInBackground: 0, off; m > 0: a finished catch-up whose swap would fold in
  /// more than m factors (those that arrived while it ran) hands its tree to another catch-up,
  /// up to catch_up_max_rounds catch-ups a job, so the swap's update folds in less.
  int catch_up_max_factors = 0;
  int catch_up_max_rounds = 3;
};

struct SmootherOptions {
  /// Fluid relinearisation thresholds β (Kaess et al., IJRR 2012, Alg. 5) on |Δ|∞ of the
  /// translational and the rotational part of a variable's tangent; GTSAM's default is 0.1 for
  /// both.
  double relinearize_threshold_translation = 0.1;
  double relinearize_threshold_rotation = 0.1;
  int relinearize_skip = 10;  ///< check for relinearisation every this many updates
  /// Wildfire threshold α of the partial state update (IJRR 2012 Alg. 7): a clique not
  /// re-eliminated is re-solved only if a separator variable moved by at least this (|·|∞)
  /// since the value the clique was last solved with.
  double wildfire_threshold = 0.001;
  bool full_backsubstitution = false;  ///< solve every clique on each update
  /// A bounded back-substitution (Extension, docs/design.md "A bounded back-substitution").
  /// 0: each update solves every clique the wildfire reaches. > 0: an update's back-
  /// substitution reads about this many MB of conditionals ([L; Sᵀ],
  /// PartialSolve::solveEntries) at most, or what the cliques it re-eliminated or folded into
  /// hold if that is more (those are always solved); the other cliques the wildfire reaches
  /// past it keep the Δ of an earlier update until a later update's budget reaches them,
  /// oldest first (UpdateStats::cliques_deferred; solveDeferred() and relinearizeAll() solve
  /// them all). The walk is then on one thread. Needs Gauss–Newton and not
  /// full_backsubstitution.
  double solve_budget_mb = 0;
  /// Fold an update made only of factors between variables already in the tree (nothing
  /// relinearised) into the Bayes tree by rank updates along their paths to the root, instead
  /// of re-eliminating those paths (false: always re-eliminate, as GTSAM's iSAM2).
  bool rank_updates = true;
  /// The newest pose (the last one added) is ordered with the touched variables, last, in
  /// every re-eliminated top that holds it (docs/design.md, "The newest pose stays last").
  /// iSAM2 constrains only the variables of the update's own factors; an update that adds
  /// none (a relinearisation, or a reweighting, alone: robust smoothing's closures rejected on
  /// entry, its graduation steps) then orders the newest pose anywhere in its top, and the next
  /// pose's odometry re-eliminates the path from its clique to the root. false: iSAM2's
  /// constraint alone. Where every update touches the newest pose (a file replayed in order
  /// of max(i, j)) it changes nothing.
  bool newest_last = true;
  /// Powell's dogleg instead of Gauss–Newton (as GTSAM's ISAM2DoglegParams). Each dogleg update
  /// evaluates F and the gradient over the whole graph (O(n), as in GTSAM).
  bool dogleg = false;
  double dogleg_initial_radius = 1.0;  ///< initial trust-region radius Δ₀
  double dogleg_min_radius = 1e-5;     ///< give up shrinking below this
  /// relinearizeAll: stop when |F_old − F_new| / F_old falls below this, or after this many
  /// iterations.
  double finalize_relative_tolerance = 1e-6;
  int finalize_max_iterations = 10;
  /// A re-eliminated top of at least this many variables is ordered by nested dissection
  /// (CHOLMOD/METIS, bayestree/elimination_plan.h) instead of CCOLAMD; the variables of the new
  /// factors still go last. −1: automatic, 100 for SE(3) (measured: replay total on the shared
  /// 3D sets 15–45% lower, docs/benchmarks.md) and never by size for SE(2) (23–28% higher on
  /// M3500, manhattan: the cheaper 3×3 eliminations do not pay for the ordering), but a 2D top
  /// whose CCOLAMD plan costs more than 2·10⁴ flops a variable is ordered both ways and the
  /// cheaper plan kept (bayestree::planTop); 0: always.
  int nested_dissection_min = -1;
  /// Threads that work on one update: the caller's and threads − 1 helpers (owned by the
  /// smoother, idle between updates), which eliminate and back-substitute independent subtrees
  /// of the Bayes tree side by side. The estimate does not depend on it, bit for bit. 0: one per
  /// core, at most 4. The BLAS should then run one thread per call (a multi-threaded OpenBLAS
  /// competes for the same cores): the constructor calls useOneBlasThread (core/blas_threads.h).
  int threads = 0;
  BatchSwitchOptions batch;  ///< when an update re-eliminates the whole graph
  /// Inline (the default: every estimate is the exact iSAM2 one of its update) or on a
  /// background thread (bounded latency on graphs whose relinearisation steps re-eliminate most
  /// of the tree). Async needs Gauss–Newton (not dogleg).
  RelinearizationMode relinearize = RelinearizationMode::kInline;
  AsyncRelinearizationOptions async;
  CachedFactorOptions cached_factors;  ///< which cliques keep their cached factor
};

struct UpdateStats {
  int new_factors = 0;
  int new_variables = 0;
  int cliques_reeliminated = 0;    ///< cliques of the new top of the tree
  int variables_reeliminated = 0;  ///< frontal variables of the new top
  /// cliques given a rank update instead (new factors between variables already in the tree)
  int cliques_updated = 0;
  int variables_relinearized = 0;
  int indeterminate_cliques = 0;  ///< nearly singular cliques that had to be damped
  int cliques_solved = 0;         ///< cliques re-solved by back-substitution
  /// after the update: cliques whose solve SmootherOptions::solve_budget_mb left for later
  /// updates (their poses keep an earlier update's Δ)
  int cliques_deferred = 0;
  /// of the cliques re-eliminated and solved, those done by the smoother's helper threads
  /// (SmootherOptions::threads)
  int cliques_on_helpers = 0;
  /// 1 when this update re-eliminated the whole graph with a fresh ordering (BatchSwitchOptions:
  /// its top was too large, or the tree's ordering had decayed)
  int batch_reeliminations = 0;
  /// variables whose Δ the relinearisation check (Alg. 5) examined: those solved since the
  /// previous check, not every variable
  int variables_checked = 0;
  /// RelinearizationMode::kAsync: 1 when this update took a snapshot and started the
  /// background relinearisation, 1 when it swapped the relinearised tree in (with the
  /// variables that snapshot relinearised in variables_relinearized)
  int async_started = 0;
  int async_swapped = 0;
  /// AsyncCatchUp::kInBackground: 1 when this update handed the finished job's tree to the
  /// catch-up (swapped in by a later update, async_swapped)
  int async_catch_up_started = 0;
  /// 1 when a relinearisation job or its catch-up was in flight after this update
  int async_pending = 0;
  /// relinearizeAll / OnlineSmoother::finalize: the iterations (relinearise-all passes) run, and
  /// whether the caller's token stopped them before convergence
  int refine_iterations = 0;
  bool cancelled = false;
  double time_s = 0.0;
  /// Where time_s went, by Alg. 6's steps (seconds of the calling thread's wall clock; what
  /// is left of time_s is the bookkeeping between them). swap_s: kAsync, a finished job's tree
  /// taken or handed to the catch-up (else 0); prepare_s: steps 1–3 and Alg. 4 step 2 (the new
  /// factors, Alg. 5, the list to linearise); top_s: step 4, the top re-eliminated (Alg. 4) or
  /// the new factors folded in; solve_s: step 5, the partial state update (Alg. 7).
  double swap_s = 0.0, prepare_s = 0.0, top_s = 0.0, solve_s = 0.0;
  /// Σ F³/3 + F²S + FS² (BayesTree::cliqueFlops) of the cliques step 4 eliminated: the
  /// re-elimination's dense work, which sets top_s when the top holds large cliques
  double reelimination_flops = 0.0;
};

/// Adds s's counts, phase times and flops to `total` (time_s, the caller's to set, and
/// async_pending and cliques_deferred, the state after s, excepted).
void addUpdateCounts(UpdateStats* total, const UpdateStats& s);

/// Memory held by the Bayes tree (bytes of double storage) and the shape of its cliques.
struct TreeMemory {
  size_t clique_bytes = 0;           ///< conditionals and cached factors in use
  size_t clique_bytes_reserved = 0;  ///< allocated for them (≥ clique_bytes)
  size_t scratch_bytes = 0;          ///< elimination scratch
  int cliques = 0, free_cliques = 0;
  int max_frontal_dim = 0, max_separator_dim = 0;
  double mean_separator_dim = 0;
};

template <class G>
class IncrementalSmoother {
 public:
  static constexpr int kDoF = G::kDoF;
  using Tangent = typename G::Tangent;
  using Edge = RelativePoseEdge<G>;

  explicit IncrementalSmoother(SmootherOptions options = {});
  ~IncrementalSmoother();
  IncrementalSmoother(const IncrementalSmoother&);
  IncrementalSmoother& operator=(const IncrementalSmoother&);
  IncrementalSmoother(IncrementalSmoother&&) noexcept;
  IncrementalSmoother& operator=(IncrementalSmoother&&) noexcept;

  /// A pose held fixed at `value` (a gauge pose); returns its dense index.
  int addFixedPose(const G& value);
  /// A new variable with initial estimate `initial`; returns its dense index.
  int addPose(const G& initial);
  /// Queues a factor (dense indices of added poses) until update(): a relative pose, a pose
  /// prior or a position prior (core/factor.h). Throws std::invalid_argument on a bad index, a
  /// self-loop or a non-finite or non-positive-definite measurement/information.
  void addFactor(const Factor<G>& factor);

  /// Makes a fixed pose a variable (an anchor no longer needed: its component joined another,
  /// or priors now fix its gauge). The next update() re-eliminates the cliques of its factors.
  /// Throws std::invalid_argument if `index` is not a fixed pose.
  void releaseFixedPose(int index);
  /// Moves the given poses rigidly: θ_v ← T θ_v (so estimate(v) ← T estimate(v)). A relative-pose
  /// factor between two of them keeps its whitened linearisation and Δ (the errors and right
  /// Jacobians are invariant under x ↦ T x), so nothing of the Bayes tree changes for it; every
  /// other factor on them (a prior, an edge to a pose not moved) is relinearised and its
  /// cliques re-eliminated by the next update(). O(Σ degree). Throws std::invalid_argument on a
  /// bad index or a non-finite T.
  void transformPoses(const std::vector<int>& indices, const G& T);

  /// Sets the inlier weight w ∈ [0, 1] of factor `index` (factors() order): the seam a robust
  /// layer reweights through (online GNC, taking an edge back). Every factor enters the linear
  /// system scaled by √w (Factor::linearizeWeighted; w = 1 changes nothing, bit for bit), so a
  /// new weight is a relinearisation of that factor: the next update() relinearises it and
  /// re-eliminates the cliques of its keys (with their ancestors), as Alg. 4 does for the
  /// factors of a relinearised variable. w = 0 leaves the factor in the graph (factors(),
  /// objective()) but takes it out of the elimination: it adds no fill and no clique holds it,
  /// so the Bayes tree is that of the graph without it; the next update re-eliminates its keys'
  /// cliques without it once. From w = 0 to w > 0 it enters the next update as a new factor
  /// would (its keys touched, a fold-in when it can be). No-op when w is its weight already.
  /// Index numFactors() + k names the k-th factor queued since the last update() (addFactor
  /// order): it enters with weight w (at w = 0, into factors() only). Throws
  /// std::invalid_argument on a bad index or w ∉ [0, 1].
  void setFactorWeight(int index, double w);

  /// Takes the factor queued as index numFactors() + k (addFactor order, as setFactorWeight
  /// names it; a FactorError names it so) out of the queue: the factors queued after it move
  /// down by one. Throws std::invalid_argument if no such factor is queued.
  void discardQueuedFactor(int index);

  /// One step of iSAM2 (IJRR 2012 Alg. 6): adds the queued factors and poses, relinearises,
  /// re-eliminates the affected top of the Bayes tree (or folds the new factors in) and updates
  /// Δ. The estimate is current on return.
  ///
  /// All or nothing (docs/library.md, "When an update throws"): when a factor's evaluation fails
  /// (a factor of your own whose error function throws, or returns a non-finite value or a
  /// wrong shape, at the point the update linearises it), update() throws FactorError
  /// (core/factor_error.h: the factor's index, name, poses and their values; the cause nested)
  /// and the smoother is exactly as before the call: the same estimate, tree and factors, and
  /// the queue (poses, factors, weights, moves) still waiting; discardQueuedFactor takes a
  /// failing queued factor out. Factors of your own are linearised first, before anything of
  /// the tree changes; what the undo restores is O(the queue and the relinearised variables),
  /// and a graph without factors of your own takes none of it. Exceptions: in kAsync mode a
  /// finished background relinearisation the update swapped in before the failure stays
  /// swapped in; with dogleg, a trial step at which a factor fails is rejected (the radius
  /// shrinks) instead of throwing.
  UpdateStats update();
  /// Relinearises every variable, re-eliminates the whole tree and back-substitutes fully,
  /// repeated until F changes by less than finalize_relative_tolerance (relative) or
  /// finalize_max_iterations. Adds queued factors first (an update(), all or nothing). A factor
  /// that fails in an iteration throws FactorError with that iteration undone: the estimate is
  /// the last completed iteration's. With a token, checks it before each
  /// iteration (one cancelled() call each) and stops when it is cancelled: the estimate is then
  /// that of the last iteration completed (UpdateStats::cancelled); an iteration is never cut
  /// in the middle. Returns the summed stats.
  UpdateStats relinearizeAll(const CancellationToken* cancel = nullptr);
  /// SmootherOptions::solve_budget_mb: solves every clique the budget deferred, so the
  /// estimate is the one the updates would have given without a budget (to the wildfire
  /// threshold); updatedPoses() lists the poses it moved. `budget_mb` > 0: about that much of
  /// the backlog only, oldest first (a caller with idle time solves it in slices). No-op
  /// without a backlog.
  UpdateStats solveDeferred(double budget_mb = 0);
  /// SmootherOptions::solve_budget_mb: the cliques whose solve is deferred now.
  int cliquesDeferred() const;
  /// RelinearizationMode::kAsync: whether a background relinearisation has been started and not
  /// yet swapped in (it is swapped in by a later update()).
  bool relinearizationPending() const;
  /// RelinearizationMode::kAsync: while `busy`, no background relinearisation starts and a
  /// check relinearises inline (the second core is taken, e.g. by a batch refinement: one
  /// background job at a time, docs/design.md). One already running goes on.
  void setSecondCoreBusy(bool busy);

  std::vector<G> estimate() const;  ///< θ ⊞ Δ for every pose (O(n))
  G estimate(int index) const;
  /// The poses whose estimate the last update() (or relinearizeAll()) may have changed, in
  /// increasing order: those of the cliques it solved, the new ones and those moved by
  /// transformPoses since the update before (every variable after a dogleg step or
  /// relinearizeAll). O(what the update touched); a pose not listed kept its estimate bit for
  /// bit.
  const std::vector<int>& updatedPoses() const;
  /// Flops of factorising the Bayes tree in its current ordering (Σ F³/3 + F²S + FS² over its
  /// cliques, F and S the frontal and separator dimensions), kept up to date by every update.
  double factorizationFlops() const;
  /// Doubles the Bayes tree's matrices need in its current ordering (Σ F(F+S) + F + S² + S over
  /// its cliques: conditional, d, cached factor; S² + S only for those that keep their cached
  /// factor, CachedFactorOptions), kept up to date likewise.
  double factorizationDoubles() const;
  const std::vector<G>& linearizationPoint() const;
  const std::vector<Tangent>& delta() const;  ///< Δ per pose (zero for fixed poses)
  double objective() const;                   ///< F = Σ eᵀΩe at estimate() (O(m))
  /// Σ w eᵀΩe at estimate(), w each factor's inlier weight: the objective the linear system
  /// models (= objective() while every weight is 1). O(m).
  double weightedObjective() const;
  /// Throws std::logic_error describing the first violated Bayes-tree invariant.
  void checkInvariants() const;

  int numCliques() const;
  TreeMemory memory() const;  ///< O(cliques)
  int numPoses() const;
  int numFactors() const;  ///< factors added by update() (not the queued ones)
  bool isFixed(int index) const;
  const std::vector<Factor<G>>& factors() const;  ///< added by update(), in order
  const SmootherOptions& options() const;

  /// Marginal covariances (bayestree/marginals.h; docs/design.md, "Marginal covariances"): of the
  /// linear system the Bayes tree holds after the last update(), i.e. of the tangent τ at the
  /// linearisation point θ (x = θ ⊞ τ, linearizationPoint(); the tangent at estimate() to first
  /// order in Δ), in the gauge of the fixed poses; a fixed pose's is zero. One forward
  /// substitution along the path from the pose's clique to the root (nothing is cached). Throws
  /// std::out_of_range for a bad index, std::logic_error for a pose that has not been through
  /// update() yet.
  Eigen::Matrix<double, kDoF, kDoF> marginalCovariance(int index) const;
  /// The joint covariance [[Σ_aa, Σ_ab], [Σ_ba, Σ_bb]] of poses a and b (as marginalCovariance;
  /// Σ_ab = 0 between components), e.g. for a Mahalanobis gate on a candidate edge a → b: two
  /// forward substitutions along the poses' paths, Σ_ab summed over the cliques they share.
  Eigen::Matrix<double, 2 * kDoF, 2 * kDoF> jointMarginalCovariance(int a, int b) const;
  /// How predictionCovariance reads the tree: kOnce, one forward substitution along the two
  /// poses' paths to the root (TreeMarginals::predicted), for a single query; kKept, from each
  /// pose's path solve, kept until the tree next changes (TreeMarginals::jointKept), for many
  /// queries on one tree (each pose's path is solved once).
  enum class PredictionPaths { kOnce, kKept };
  /// A Σ Aᵀ for a candidate factor on poses a and b with whitened Jacobian blocks A_a, A_b
  /// (Σ their joint covariance, as jointMarginalCovariance): the covariance its whitened residual
  /// is predicted with, beside the factor's own I. A fixed pose contributes nothing. Throws as
  /// jointMarginalCovariance.
  Eigen::Matrix<double, kDoF, kDoF> predictionCovariance(
      int a, const Eigen::Matrix<double, kDoF, kDoF>& A_a, int b,
      const Eigen::Matrix<double, kDoF, kDoF>& A_b,
      PredictionPaths paths = PredictionPaths::kOnce) const;
  /// An upper bound B ⪰ A Σ Aᵀ (Loewner order) of predictionCovariance from the two poses'
  /// marginals alone, without Σ_ab: B = 2 (A_a Σ_aa A_aᵀ + A_b Σ_bb A_bᵀ), since
  /// 2 diag(Σ_aa, Σ_bb) − Σ = J Σ J ⪰ 0 with J = diag(I, −I). The marginals as kKept reads
  /// them (TreeMarginals::marginalKept: keepSharedCliqueJoints' walk, else a kept path solve),
  /// so after keepSharedCliqueJoints it costs no path solve for the poses the walk reached.
  /// Throws as predictionCovariance.
  Eigen::Matrix<double, kDoF, kDoF> predictionCovarianceBound(
      int a, const Eigen::Matrix<double, kDoF, kDoF>& A_a, int b,
      const Eigen::Matrix<double, kDoF, kDoF>& A_b) const;
  /// Before many kKept queries on one tree: the joint covariance of every pair of poses that
  /// share a clique (the two poses of every factor the tree holds) read off one walk down the
  /// tree instead of each pose's path solve (TreeMarginals::keepSharedCliqueJoints), kept until
  /// the tree next changes; the same values to rounding. Pairs that share no clique are left
  /// to the path solves. Returns how many pairs it kept.
  int keepSharedCliqueJoints(const std::vector<std::pair<int, int>>& pose_pairs) const;
  /// Every pose's marginal covariance (as marginalCovariance), in one walk down the tree that
  /// holds the joints of one path at a time (not the cache). Throws std::logic_error if a pose
  /// has not been through update() yet.
  std::vector<Eigen::Matrix<double, kDoF, kDoF>> marginalCovariances() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

using IncrementalSmoother2 = IncrementalSmoother<SE2>;
using IncrementalSmoother3 = IncrementalSmoother<SE3>;

extern template class IncrementalSmoother<SE2>;
extern template class IncrementalSmoother<SE3>;

}  // namespace arbor
