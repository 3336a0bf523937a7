// The smoother: IJRR 2012 Alg. 6 (one step of iSAM2) over the units of bayestree/ — the Bayes
// tree (bayes_tree.h), the linearised factors (linear_factors.h), the top elimination
// (top_elimination.h), the fold-in (fold_in.h, our extension) and the partial state update
// (partial_solve.h), with the threads they share (update_threads.h). Numbers are those of
// Kaess et al., "iSAM2: Incremental smoothing and mapping using the Bayes tree", IJRR 31(2),
// 2012 (the ICRA 2011 paper numbers its listings differently): Alg. 3 the Bayes-tree update with
// new factors, Alg. 4 the same with fluid relinearisation, Alg. 5 fluid relinearisation, Alg. 6
// one step of iSAM2, Alg. 7 the partial state update. Steps marked "Extension" are ours
// (docs/design.md, "The update, step by step").
#include "arbor_slam/bayestree/incremental_smoother.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>
#include <variant>

#include <Eigen/Core>

#include "arbor_slam/bayestree/async_relinearization.h"
#include "arbor_slam/bayestree/background_job.h"
#include "arbor_slam/bayestree/bayes_tree.h"
#include "arbor_slam/bayestree/dogleg_step.h"
#include "arbor_slam/bayestree/fold_in.h"
#include "arbor_slam/bayestree/linear_factors.h"
#include "arbor_slam/bayestree/marginals.h"
#include "arbor_slam/bayestree/partial_solve.h"
#include "arbor_slam/bayestree/top_elimination.h"
#include "arbor_slam/bayestree/tree_shape.h"
#include "arbor_slam/bayestree/update_threads.h"
#include "arbor_slam/core/blas_threads.h"
#include "arbor_slam/core/elapsed.h"
#include "arbor_slam/core/finite_pose.h"
#include "arbor_slam/core/information.h"

namespace arbor {

void addUpdateCounts(UpdateStats* total, const UpdateStats& s) {
  total->new_factors += s.new_factors;
  total->new_variables += s.new_variables;
  total->cliques_reeliminated += s.cliques_reeliminated;
  total->variables_reeliminated += s.variables_reeliminated;
  total->variables_relinearized += s.variables_relinearized;
  total->indeterminate_cliques += s.indeterminate_cliques;
  total->cliques_solved += s.cliques_solved;
  total->cliques_updated += s.cliques_updated;
  total->cliques_on_helpers += s.cliques_on_helpers;
  total->batch_reeliminations += s.batch_reeliminations;
  total->variables_checked += s.variables_checked;
  total->async_started += s.async_started;
  total->async_swapped += s.async_swapped;
  total->async_catch_up_started += s.async_catch_up_started;
  total->refine_iterations += s.refine_iterations;
  total->cancelled = total->cancelled || s.cancelled;
  total->swap_s += s.swap_s;
  total->prepare_s += s.prepare_s;
  total->top_s += s.top_s;
  total->solve_s += s.solve_s;
  total->reelimination_flops += s.reelimination_flops;
}

namespace {

using Clock = std::chrono::steady_clock;

void accumulate(UpdateStats* total, const UpdateStats& s) {
  addUpdateCounts(total, s);
  total->async_pending = s.async_pending;  // the state after the last update
  total->cliques_deferred = s.cliques_deferred;
}

int threadCount(int requested) {
  if (requested < 0)
    throw std::invalid_argument("IncrementalSmoother: bad option threads = " +
                                std::to_string(requested));
  if (requested > 0) return requested;
  return static_cast<int>(std::clamp(std::thread::hardware_concurrency(), 1u, 4u));
}

void validate(const SmootherOptions& o) {
  auto bad = [](const std::string& what, double v, const char* must) {
    std::ostringstream msg;
    msg << "IncrementalSmoother: bad option " << what << " = " << v << " (must be " << must << ")";
    throw std::invalid_argument(msg.str());
  };
  if (!(o.relinearize_threshold_translation >= 0))
    bad("relinearize_threshold_translation", o.relinearize_threshold_translation, "≥ 0");
  if (!(o.relinearize_threshold_rotation >= 0))
    bad("relinearize_threshold_rotation", o.relinearize_threshold_rotation, "≥ 0");
  if (o.relinearize_skip < 1) bad("relinearize_skip", o.relinearize_skip, "≥ 1");
  if (o.nested_dissection_min < -1) bad("nested_dissection_min", o.nested_dissection_min, "≥ −1");
  if (!(o.wildfire_threshold >= 0)) bad("wildfire_threshold", o.wildfire_threshold, "≥ 0");
  if (!(o.dogleg_initial_radius > 0)) bad("dogleg_initial_radius", o.dogleg_initial_radius, "> 0");
  if (!(o.dogleg_min_radius > 0)) bad("dogleg_min_radius", o.dogleg_min_radius, "> 0");
  if (!(o.finalize_relative_tolerance >= 0))
    bad("finalize_relative_tolerance", o.finalize_relative_tolerance, "≥ 0");
  if (o.finalize_max_iterations < 1)
    bad("finalize_max_iterations", o.finalize_max_iterations, "≥ 1");
  if (!(o.batch.top_share > 0 && o.batch.top_share <= 1))
    bad("batch.top_share", o.batch.top_share, "in (0, 1]");
  if (!(o.batch.reorder_decay == 0 || o.batch.reorder_decay >= 1))
    bad("batch.reorder_decay", o.batch.reorder_decay, "0 or ≥ 1");
  if (o.batch.constrain_last_max < 1)
    bad("batch.constrain_last_max", o.batch.constrain_last_max, "≥ 1");
  if (o.async.min_variables < 1) bad("async.min_variables", o.async.min_variables, "≥ 1");
  if (!(o.async.reorder_decay >= 1)) bad("async.reorder_decay", o.async.reorder_decay, "≥ 1");
  if (o.async.job_iterations < 1) bad("async.job_iterations", o.async.job_iterations, "≥ 1");
  if (o.async.catch_up_max_factors < 0)
    bad("async.catch_up_max_factors", o.async.catch_up_max_factors, "≥ 0");
  if (o.async.catch_up_max_rounds < 1)
    bad("async.catch_up_max_rounds", o.async.catch_up_max_rounds, "≥ 1");
  if (o.async.swap_after_updates < 0)
    bad("async.swap_after_updates", o.async.swap_after_updates, "≥ 0");
  if (!(o.cached_factors.max_ratio >= 0 && std::isfinite(o.cached_factors.max_ratio)))
    bad("cached_factors.max_ratio", o.cached_factors.max_ratio, "finite and ≥ 0");
  if (!(o.cached_factors.min_tree_doubles >= 0))
    bad("cached_factors.min_tree_doubles", o.cached_factors.min_tree_doubles, "≥ 0");
  if (!(o.solve_budget_mb >= 0 && std::isfinite(o.solve_budget_mb)))
    bad("solve_budget_mb", o.solve_budget_mb, "finite and ≥ 0");
  if (o.solve_budget_mb > 0 && (o.dogleg || o.full_backsubstitution))
    throw std::invalid_argument(
        "IncrementalSmoother: bad options: solve_budget_mb needs Gauss–Newton and partial "
        "back-substitution (not dogleg, not full_backsubstitution)");
  if (o.relinearize == RelinearizationMode::kAsync && o.dogleg)
    throw std::invalid_argument(
        "IncrementalSmoother: bad options: relinearize = async needs Gauss–Newton, not dogleg");
}

// 2D tops (SmootherOptions::nested_dissection_min automatic) whose CCOLAMD plan costs more than
// this many flops per variable are ordered by nested dissection too, the cheaper plan kept. The
// shared 2D sets stay below it (M3500 and manhattan whole: 2·10³ a variable, where nested
// dissection costs 14–30% more in total), the generated 50,000-pose world's tops pass it (its
// whole graph: 1.1·10⁵ a variable under CCOLAMD, 3.4·10⁴ under nested dissection;
// docs/benchmarks.md, "Nested dissection for heavy 2D tops").
constexpr double kNestedDissectionTryFlops = 2e4;
// The decay check (BatchSwitchOptions::reorder_decay) waits until the tree's factorisation
// costs at least this many flops, or its matrices hold this many doubles (8 MB): below them a
// re-ordering saves less than the check costs.
constexpr double kMinDecayCheckFlops = 1e6;
// The queue of factors keeps its storage between updates up to this many factors.
constexpr size_t kKeptQueueCapacity = 4096;
constexpr double kMinDecayCheckDoubles = 1e6;

/// How one pass of Alg. 6 runs.
struct StepOptions {
  /// relinearizeAll: relinearise every variable and re-eliminate the whole tree (the top
  /// unconstrained); never a fold-in.
  bool relinearize_all = false;
  /// Alg. 5 in this pass (every relinearize_skip-th update).
  bool check_relinearization = false;
  /// Alg. 7 at the end (false: a fold-in pass follows, which solves).
  bool solve = true;
};

}  // namespace

template <class G>
struct IncrementalSmoother<G>::Impl {
  static constexpr int D = G::kDoF;
  static constexpr int kTrans = G::kDim;  // the first kDim tangent entries are translational
  using Vec = Tangent;

  SmootherOptions opt;
  // Θ, the gauge poses (constants) and Δ, the step applied (Gauss–Newton or dogleg).
  std::vector<G> theta;
  std::vector<char> fixed;
  std::vector<Vec> delta;
  // The units.
  bayestree::BayesTree<D> tree;
  bayestree::LinearizedFactors<G> factors;  // every factor added by update(), in order
  bayestree::TopElimination<G> top_elimination;
  bayestree::FoldIn<G> fold_in;
  bayestree::PartialSolve<D> partial_solve;  // Δ_newton
  bayestree::UpdateThreads threads;
  // Marginal covariances: the path solves' scratch (bayestree/marginals.h).
  mutable bayestree::TreeMarginals<D> marginals;
  // Waiting for the next update.
  std::vector<Factor<G>> queued;
  std::vector<int> new_vars;
  std::vector<int> to_touch;        // variables whose cliques the next update re-eliminates
  std::vector<int> to_relinearize;  // factors the next update relinearises (transformPoses)
  std::vector<int> readmitted;      // factors from weight 0 to > 0: enter the next update anew
  int update_count = 0;
  int stamp = 0;  // one per pass: factors.stamp lists a factor once
  double dogleg_radius = 1.0;
  // Per pose, 1 while it is among the pass's touched variables (new, or of a new factor);
  // restored to 0.
  std::vector<char> mark;
  // A pass's lists (reused).
  std::vector<int> touched, relin, to_linearize, marked;
  typename bayestree::BayesTree<D>::Top top;
  // updatedPoses(): the poses of the last update (each once: updated_stamp[v] == publish_stamp),
  // every variable when updated_all; `moved` waits for the next update (transformPoses).
  // Sorted when first asked for (updated_is_sorted), not by every update: a replay never asks, and
  // sorting a few hundred solved poses an update was 4% of intel's update instructions.
  mutable std::vector<int> updated;
  std::vector<int> moved, updated_stamp;
  int publish_stamp = 0;
  bool updated_all = false;
  mutable bool updated_is_sorted = true;
  // Alg. 5's candidates: the variables solved since the last relinearisation check (each once:
  // is_candidate), the only ones whose Δ can have crossed β; every variable when check_all
  // (after a step that set Δ everywhere: dogleg, relinearizeAll).
  std::vector<int> relin_candidates;
  std::vector<char> is_candidate;
  bool check_all = false;
  // The batch switch (BatchSwitchOptions): the variables (not fixed), the tree's flops and
  // doubles when its ordering was last compared with a fresh one (or made afresh), and a
  // re-ordering found due.
  int num_variables = 0;
  double flops_reference = 0, doubles_reference = 0;
  bool reorder_due = false;
  // AsyncRelinearizationOptions::reorder_in_background: a decay found, its re-ordering left to
  // a job (started at the next update's snapshot; cleared when a fresh tree comes in).
  bool reorder_job_wanted = false;
  bayestree::RowList fresh_rows;
  std::vector<int> fresh_vars;
  // RelinearizationMode::kAsync (bayestree/async_relinearization.h): the job in flight, what
  // changed since its snapshot that the swap folds in besides the poses and factors added since
  // (poses moved, factors reweighted, anchors released), and whether the second core is taken.
  bayestree::AsyncRelinearization<G> async;
  std::vector<int> moved_since_snapshot, reweighted_since_snapshot, released_since_snapshot;
  // AsyncCatchUp::kInBackground: the catch-up in flight (a copy of this state that folds the
  // job's tree up to the update that started it), that update's poses and factors, Θ then, and
  // |M| of the job's snapshot.
  bayestree::BackgroundJob<Impl> catch_up;
  int catch_up_poses = 0, catch_up_factors = 0, catch_up_relinearized = 0, catch_up_rounds = 0;
  std::vector<G> theta_at_catch_up;
  // What the last swap replaced (its tree, linearisations, solve and Δ), freed by the next
  // relinearisation job's thread before its work (AsyncRelinearization::start), or by
  // relinearizeAll, which re-eliminates everything anyway (and frees snapshot_factors too).
  bayestree::RelinearizedTree<G> replaced;
  // The last snapshot's factor array, kept for the next snapshot to copy into.
  std::vector<Factor<G>> snapshot_factors;
  int pass_first_factor = 0;  // the first factor of the current pass (the snapshot's end)
  bool second_core_busy = false;

  explicit Impl(const SmootherOptions& o)
      : opt(o), threads(threadCount(o.threads)), dogleg_radius(o.dogleg_initial_radius) {
    validate(o);
    tree.cached_factors = o.cached_factors;
  }

  int numPoses() const { return static_cast<int>(theta.size()); }
  // predictionCovariance's poses: in range and in the tree (or fixed).
  void checkPredictionPoses(int a, int b) const {
    for (int v : {a, b}) {
      if (v < 0 || v >= numPoses())
        throw std::out_of_range("IncrementalSmoother: prediction covariance on pose index " +
                                std::to_string(v) + ": out of range (" +
                                std::to_string(numPoses()) + " poses)");
      if (!fixed[v] && tree.clique_of[v] < 0)
        throw std::logic_error("IncrementalSmoother: prediction covariance on pose index " +
                               std::to_string(v) +
                               ": not in the Bayes tree yet (call update() first)");
    }
  }
  // A relinearisation job or its catch-up in flight (no check runs; changes are recorded).
  bool relinearizationPending() const { return async.pending() || catch_up.pending(); }
  // Per pose, 1 when it is not a variable of the tree: held fixed, or not in it (yet).
  std::vector<char> notInTree() const {
    std::vector<char> out(static_cast<size_t>(numPoses()));
    for (int v = 0; v < numPoses(); ++v) out[v] = fixed[v] || tree.clique_of[v] < 0 ? 1 : 0;
    return out;
  }

  int addPose(const G& x, bool is_fixed) {
    if (!allFinite(x)) throw std::invalid_argument("IncrementalSmoother::addPose: not finite");
    const int index = numPoses();
    theta.push_back(x);
    fixed.push_back(is_fixed);
    delta.push_back(Vec::Zero());
    partial_solve.addVariable();
    tree.addVariable();
    factors.addVariable();
    threads.addVariable();
    mark.push_back(0);
    updated_stamp.push_back(0);
    is_candidate.push_back(0);
    if (!is_fixed) {
      new_vars.push_back(index);
      ++num_variables;
    }
    return index;
  }

  void addFactor(const Factor<G>& f) {
    std::string where = "IncrementalSmoother::addFactor(" + f.name();
    for (int k = 0; k < f.arity(); ++k) where += (k ? ", " : " ") + std::to_string(f.key(k));
    where += "): ";
    for (int k = 0; k < f.arity(); ++k)
      if (f.key(k) < 0 || f.key(k) >= numPoses())
        throw std::invalid_argument(where + "pose index out of range (" +
                                    std::to_string(numPoses()) + " poses)");
    if (f.arity() == 2 && f.key(0) == f.key(1)) throw std::invalid_argument(where + "self-loop");
    if (!f.isFinite()) throw std::invalid_argument(where + "measurement or information not finite");
    const std::string problem =
        std::visit([](const auto& x) { return informationProblem(x.information); }, f.variant());
    if (!problem.empty()) throw std::invalid_argument(where + "information matrix " + problem);
    queued.push_back(f);
  }

  // Extension (the online layer's components): a released anchor's factors were unary terms on
  // their other keys, assembled in those keys' cliques; these are re-eliminated with v as a
  // variable.
  void releaseFixedPose(int v) {
    if (v < 0 || v >= numPoses() || !fixed[v])
      throw std::invalid_argument("IncrementalSmoother::releaseFixedPose: " + std::to_string(v) +
                                  " is not a fixed pose");
    fixed[v] = 0;
    new_vars.push_back(v);
    ++num_variables;
    if (relinearizationPending()) released_since_snapshot.push_back(v);
    for (int f : factors.var_factors[v]) {
      const Factor<G>& e = factors.factors[f];
      for (int k = 0; k < e.arity(); ++k)
        if (e.key(k) != v && !fixed[e.key(k)]) to_touch.push_back(e.key(k));
    }
  }

  // Extension (the online layer's components): θ_v ← T θ_v; the factors not invariant under
  // the move are relinearised and their cliques re-eliminated by the next update.
  void transformPoses(const std::vector<int>& poses, const G& T) {
    if (!allFinite(T))
      throw std::invalid_argument("IncrementalSmoother::transformPoses: transform not finite");
    for (int v : poses)
      if (v < 0 || v >= numPoses())
        throw std::invalid_argument("IncrementalSmoother::transformPoses: index " +
                                    std::to_string(v) + " out of range");
    for (int v : poses) mark[v] = 1;
    moved.insert(moved.end(), poses.begin(), poses.end());
    if (relinearizationPending())
      moved_since_snapshot.insert(moved_since_snapshot.end(), poses.begin(), poses.end());
    for (int v : poses) {
      theta[v] = T.compose(theta[v]);
      theta[v].normalize();
      for (int f : factors.var_factors[v]) {
        const Factor<G>& e = factors.factors[f];
        if (e.kind() == FactorKind::kRelativePose && mark[e.key(0)] && mark[e.key(1)]) continue;
        to_relinearize.push_back(f);  // not invariant: relinearised at the moved θ
        for (int k = 0; k < e.arity(); ++k)
          if (!fixed[e.key(k)]) to_touch.push_back(e.key(k));
      }
    }
    for (int v : poses) mark[v] = 0;
  }

  // Extension (robust layers): a new inlier weight is a relinearisation of the factor, so its
  // keys' cliques are re-eliminated by the next update. Weight 0 takes the factor out of the
  // structure (LinearizedFactors::attached; its keys' cliques are re-eliminated without it
  // once), and a factor that leaves weight 0 enters the next update as a new factor would:
  // its keys are touched, it is linearised, and it may be folded in.
  // A queued factor (index numFactors() + k, k in addFactor order) takes the weight before it
  // enters: its first linearisation is weighted, nothing is relinearised (at weight 0 it never
  // enters the structure).
  void setFactorWeight(int f, double w) {
    const int added = factors.numFactors();
    const int all = added + static_cast<int>(queued.size());
    if (f < 0 || f >= all)
      throw std::invalid_argument("IncrementalSmoother::setFactorWeight: factor " +
                                  std::to_string(f) + " out of range (" + std::to_string(all) +
                                  " factors, queued included)");
    if (!(w >= 0 && w <= 1))
      throw std::invalid_argument("IncrementalSmoother::setFactorWeight(" + std::to_string(f) +
                                  "): weight " + std::to_string(w) + " not in [0, 1]");
    if (f >= added) {
      queued[static_cast<size_t>(f - added)].setInlierWeight(w);
      return;
    }
    Factor<G>& e = factors.factors[f];
    if (e.inlierWeight() == w) return;
    e.setInlierWeight(w);
    if (relinearizationPending()) reweighted_since_snapshot.push_back(f);
    if (w > 0 && !factors.attached[f]) {
      readmitted.push_back(f);  // attached by the next update (addNewFactorsAndVariables)
      return;
    }
    if (w > 0) {
      to_relinearize.push_back(f);
    } else {
      factors.detach(f);
    }
    for (int k = 0; k < e.arity(); ++k)
      if (!fixed[e.key(k)]) to_touch.push_back(e.key(k));
  }

  TreeMemory memory() const {
    TreeMemory m = tree.memory();
    m.scratch_bytes =
        fold_in.scratchBytes() + threads.scratchBytes() + top_elimination.scratchBytes();
    return m;
  }

  typename bayestree::FoldIn<G>::Context foldInContext() {
    return {factors, theta, fixed, threads.lanes[0].slot};
  }

  // ---- The update --------------------------------------------------------------------------

  // One update: Alg. 6, in one pass, or (Extension: split) in two. When new poses arrive with
  // factors a rank update could take (a pose with its loop closures, --step pose), the factors
  // that bring the new poses into the tree go first (a pass of Alg. 6 without its solve) and
  // the others are folded in by a second pass: the linear system, hence the step, is that of
  // one update with all of them.
  UpdateStats update() {
    beginUpdated();
    UpdateStats st = updatePasses();
    finishUpdated();
    return st;
  }

  // updatedPoses(): starts the list with the poses moved since the last update.
  void beginUpdated() {
    ++publish_stamp;
    updated.clear();
    updated_all = false;
    for (int v : moved) noteUpdated(v);
    moved.clear();
  }
  void noteUpdated(int v) {
    if (updated_stamp[v] == publish_stamp) return;
    updated_stamp[v] = publish_stamp;
    updated.push_back(v);
  }
  void finishUpdated() {
    if (updated_all) {
      updated.clear();
      for (int v = 0; v < numPoses(); ++v)
        if (!fixed[v]) updated.push_back(v);
    }
    updated_is_sorted = updated_all;  // the loop above lists them in order
  }
  // The list updatedPoses() returns: `updated` in increasing order, sorted once per update.
  const std::vector<int>& updatedInOrder() const {
    if (!updated_is_sorted) {
      std::sort(updated.begin(), updated.end());
      updated_is_sorted = true;
    }
    return updated;
  }
  // After a solve: its variables are updated and are the next relinearisation check's
  // candidates.
  void noteSolved() {
    for (int v : partial_solve.solved_variables) {
      noteUpdated(v);
      if (!is_candidate[v]) {
        is_candidate[v] = 1;
        relin_candidates.push_back(v);
      }
    }
  }

  UpdateStats updatePasses() {
    ++update_count;
    // RelinearizationMode::kAsync: a finished background relinearisation is swapped in first;
    // while one is in flight, no check runs (its variables wait for the swap).
    int swapped = -1;
    bool caught_up = false;
    const auto t_swap = Clock::now();
    if (async.pending() && asyncSwapDue()) {
      if (opt.async.catch_up == AsyncCatchUp::kInBackground) {
        startCatchUp();
        caught_up = true;
      } else {
        swapped = swapInRelinearized();
      }
    } else if (catch_up.pending() && catchUpSwapDue()) {
      if (catchUpAgain()) {
        restartCatchUp();
        caught_up = true;
      } else {
        swapped = swapInCaughtUp();
      }
    }
    const double swap_s = swapped >= 0 || caught_up ? secondsSince(t_swap) : 0.0;
    StepOptions pass;
    pass.check_relinearization =
        update_count % opt.relinearize_skip == 0 && !relinearizationPending();
    UpdateStats st = runPasses(pass);
    st.swap_s = swap_s;
    st.time_s += swap_s;
    if (swapped >= 0) {
      st.async_swapped = 1;
      st.variables_relinearized += swapped;
    }
    st.async_catch_up_started = caught_up ? 1 : 0;
    st.async_pending = relinearizationPending() ? 1 : 0;
    return st;
  }

  UpdateStats runPasses(const StepOptions& pass) {
    const auto weighted = [](const Factor<G>& e) { return e.inlierWeight() > 0; };
    if (!opt.rank_updates || opt.dogleg || new_vars.empty() ||
        std::count_if(queued.begin(), queued.end(), weighted) < 2 || !to_touch.empty())
      return step(pass);
    std::vector<Factor<G>> rest =
        bayestree::FoldIn<G>::splitOffIntroducing(&queued, fixed, tree, &threads.lanes[0].slot);
    // Factors of weight 0 enter no structure (LinearizedFactors::attached): they join `factors`
    // in the first pass and are left out of the choice to fold.
    const auto zero = std::stable_partition(rest.begin(), rest.end(), weighted);
    queued.insert(queued.end(), zero, rest.end());
    rest.erase(zero, rest.end());
    if (!fold_in.worthFolding(rest, fixed, &tree)) {
      queued.insert(queued.end(), rest.begin(), rest.end());
      rest.clear();
    }
    if (rest.empty()) return step(pass);
    const auto t0 = Clock::now();
    StepOptions introduce = pass;
    introduce.solve = false;
    UpdateStats st = step(introduce);
    queued.swap(rest);
    StepOptions fold;  // nothing to relinearise: Alg. 5 ran in the first pass if due
    accumulate(&st, step(fold));
    st.time_s = secondsSince(t0);
    return st;
  }

  // ---- Asynchronous relinearisation (RelinearizationMode::kAsync) ---------------------------

  // Whether background jobs may run: async mode, and the second core not taken.
  bool backgroundJobsAllowed() const {
    return opt.relinearize == RelinearizationMode::kAsync && !second_core_busy;
  }

  // At a check that marked M (`relin`, not yet applied): when M is large (or a re-ordering is
  // wanted, reorder_job_wanted), the second core free and no job in flight, snapshots what the
  // re-elimination reads — the factors of the tree (those before this pass's), Θ with
  // Θ_M := Θ_M ⊕ Δ_M, the poses held fixed (the gauge poses and those not in the tree yet) — and
  // starts the background job. O(n + m) copies.
  bool startAsyncRelinearization(UpdateStats* st) {
    if (!backgroundJobsAllowed() || relinearizationPending() ||
        (static_cast<int>(relin.size()) < opt.async.min_variables && !reorder_job_wanted))
      return false;
    bayestree::RelinearizationSnapshot<G> s;
    s.theta = theta;
    s.fixed = notInTree();
    // Into the last snapshot's buffer: its pages are in memory already, where a fresh copy of
    // the factors faults every page in on the update path (up to 117 ms at 200,000 poses,
    // measured), and the old buffer is not unmapped on it either. A quarter of room to grow.
    s.factors = std::move(snapshot_factors);
    s.factors.clear();
    const auto wanted = static_cast<size_t>(pass_first_factor);
    if (s.factors.capacity() < wanted) s.factors.reserve(wanted + wanted / 4);
    s.factors.insert(s.factors.end(), factors.factors.begin(),
                     factors.factors.begin() + pass_first_factor);
    s.relinearized = relin;
    std::sort(s.relinearized.begin(), s.relinearized.end());
    for (int v : s.relinearized) {
      s.theta_before.push_back(theta[v]);
      s.theta[v] = theta[v].retract(delta[v]);
      s.theta[v].normalize();
    }
    s.update = update_count;
    s.nested_dissection_min = nestedDissectionMin();
    s.nested_dissection_try_flops = nestedDissectionTryFlops();
    s.cached_factors = opt.cached_factors;
    s.iterations = opt.async.job_iterations;
    s.relative_tolerance = opt.finalize_relative_tolerance;
    moved_since_snapshot.clear();
    reweighted_since_snapshot.clear();
    released_since_snapshot.clear();
    async.start(std::move(s), opt.async.synchronous, std::exchange(replaced, {}));
    st->async_started = 1;
    return true;
  }

  // The swap's update: the job is done (or, with swap_after_updates, this is its update: wait).
  bool asyncSwapDue() const {
    if (opt.async.swap_after_updates > 0)
      return update_count >= async.snapshot().update + opt.async.swap_after_updates;
    return async.done();
  }

  // A tree to swap in (the job's, or the catch-up's) and what it was built from: its first n
  // poses and f factors at Θ = theta; `fixed`: per pose, not a variable of the tree (held fixed,
  // or not in it); the poses whose Θ differs from the smoother's at the base's start
  // (`relinearized`, increasing, or every pose when `all_relinearized`) with the smoother's Θ
  // then (`theta_before`, parallel, or per pose).
  struct SwapBase {
    int n = 0, f = 0;
    std::vector<char> fixed;
    std::vector<G> theta;
    std::vector<int> relinearized;
    bool all_relinearized = false;
    std::vector<G> theta_before;
    bayestree::BayesTree<D> tree;
    bayestree::LinearizedFactors<G> factors;
    bayestree::PartialSolve<D> solve;
    std::vector<Vec> delta;
  };

  static SwapBase baseOfJob(bayestree::RelinearizationSnapshot<G>&& snap,
                            bayestree::RelinearizedTree<G>&& job) {
    SwapBase b;
    b.n = static_cast<int>(snap.theta.size());
    b.f = static_cast<int>(snap.factors.size());
    b.fixed = std::move(snap.fixed);
    if (job.iterations > 1) {
      // Every pose stepped: Θ before is the smoother's at the snapshot (M's before Θ_M ⊕ Δ_M).
      std::vector<G> before = std::move(snap.theta);
      for (size_t k = 0; k < snap.relinearized.size(); ++k)
        before[static_cast<size_t>(snap.relinearized[k])] = snap.theta_before[k];
      b.theta = std::move(job.theta);
      b.all_relinearized = true;
      b.theta_before = std::move(before);
    } else {
      b.theta = std::move(snap.theta);
      b.relinearized = std::move(snap.relinearized);
      b.theta_before = std::move(snap.theta_before);
    }
    b.tree = std::move(job.tree);
    b.factors = std::move(job.factors);
    b.solve = std::move(job.solve);
    b.delta = std::move(job.delta);
    return b;
  }

  // Replaces the tree, Θ, Δ and the linearisations with the base's, and queues for the next
  // pass everything `src` (this smoother, or the owner of a catch-up) has that the base lacks,
  // as one ordinary pass folds it in: the factors added since (they keep their indices; src's
  // queue too when `with_queued`), the poses new to the base's graph (added since, or not in it,
  // or released since: their neighbours' cliques are re-eliminated), the poses moved since
  // (their Θ moved alike, their factors relinearised) and the factors reweighted since. Each
  // factor is then linearised at the base's Θ, as relinearising at the snapshot and then
  // applying the later updates inline would have it. Reads src before it writes this.
  void adopt(SwapBase&& base, const Impl& src, bool with_queued) {
    const int n = src.numPoses();
    // Θ: the base's, moved since as src's poses were (θ ← T θ for every move, i.e.
    // θ_now θ_then⁻¹ on the left; a pose not relinearised had θ_then = the base's).
    std::vector<G> new_theta = std::move(base.theta);
    std::vector<int> moved_poses = src.moved_since_snapshot;
    std::sort(moved_poses.begin(), moved_poses.end());
    moved_poses.erase(std::unique(moved_poses.begin(), moved_poses.end()), moved_poses.end());
    for (int v : moved_poses) {
      if (v >= base.n) continue;
      const G* before = nullptr;
      if (base.all_relinearized) {
        before = &base.theta_before[v];
      } else {
        const auto it = std::lower_bound(base.relinearized.begin(), base.relinearized.end(), v);
        if (it != base.relinearized.end() && *it == v)
          before = &base.theta_before[static_cast<size_t>(it - base.relinearized.begin())];
      }
      if (!before) {
        new_theta[v] = src.theta[v];
        continue;
      }
      new_theta[v] = src.theta[v].compose(before->inverse()).compose(new_theta[v]);
      new_theta[v].normalize();
    }
    for (int v = base.n; v < n; ++v) new_theta.push_back(src.theta[v]);
    // The factors added since go first in the queue (their indices stay), with the weights
    // they have now.
    std::vector<Factor<G>> requeued(src.factors.factors.begin() + base.f,
                                    src.factors.factors.end());
    if (with_queued) requeued.insert(requeued.end(), src.queued.begin(), src.queued.end());
    std::vector<std::pair<int, double>> weights;
    for (int f : src.reweighted_since_snapshot)
      if (f < base.f) weights.emplace_back(f, src.factors.factors[f].inlierWeight());
    std::vector<int> pending_relinearize;
    for (int f : src.to_relinearize)
      if (f < base.f) pending_relinearize.push_back(f);
    // The base's state becomes this smoother's; the old waits in `replaced` for the next job.
    replaced.tree = std::move(tree);
    replaced.factors = std::move(factors);
    replaced.solve = std::move(partial_solve);
    replaced.delta = std::move(delta);
    theta = std::move(new_theta);
    tree = std::move(base.tree);
    factors = std::move(base.factors);
    partial_solve = std::move(base.solve);
    delta = std::move(base.delta);
    for (int v = base.n; v < n; ++v) {
      tree.addVariable();
      factors.addVariable();
      partial_solve.addVariable();
      delta.push_back(Vec::Zero());
    }
    queued = std::move(requeued);
    to_relinearize = std::move(pending_relinearize);
    auto relinearizeFactor = [&](int f) {
      to_relinearize.push_back(f);
      const Factor<G>& e = factors.factors[f];
      for (int k = 0; k < e.arity(); ++k)
        if (!fixed[e.key(k)]) to_touch.push_back(e.key(k));
    };
    // A reweighting takes the base's factor in or out of the structure as setFactorWeight does
    // (LinearizedFactors::attached follows the weight the base had).
    for (const auto& [f, w] : weights) {
      factors.factors[f].setInlierWeight(w);
      if (w > 0 && !factors.attached[f]) {
        readmitted.push_back(f);
      } else if (w > 0) {
        relinearizeFactor(f);
      } else if (factors.attached[f]) {
        factors.detach(f);
        const Factor<G>& e = factors.factors[f];
        for (int k = 0; k < e.arity(); ++k)
          if (!fixed[e.key(k)]) to_touch.push_back(e.key(k));
      }
    }
    for (int v : moved_poses)
      if (v < base.n)
        for (int f : factors.var_factors[v]) relinearizeFactor(f);
    // The variables the base held fixed that are not (not in its tree, or released since),
    // and every variable added since: new to the base's tree.
    new_vars.clear();
    for (int v = 0; v < base.n; ++v) {
      if (!base.fixed[v] || fixed[v]) continue;
      new_vars.push_back(v);
      for (int f : factors.var_factors[v]) {
        const Factor<G>& e = factors.factors[f];
        for (int k = 0; k < e.arity(); ++k)
          if (e.key(k) != v && !fixed[e.key(k)]) to_touch.push_back(e.key(k));
      }
    }
    for (int v = base.n; v < n; ++v)
      if (!fixed[v]) new_vars.push_back(v);
    // Every Δ is the base's: the next check scans every variable; the ordering is fresh.
    for (int v : relin_candidates) is_candidate[v] = 0;
    relin_candidates.clear();
    check_all = true;
    flops_reference = tree.flops;
    doubles_reference = tree.doubles;
    reorder_due = false;
    reorder_job_wanted = false;
    updated_all = true;
    marginals = bayestree::TreeMarginals<D>();
  }

  void clearSinceSnapshot() {
    moved_since_snapshot.clear();
    reweighted_since_snapshot.clear();
    released_since_snapshot.clear();
  }

  // AsyncCatchUp::kOnSwap: the job's tree, with everything since its snapshot queued for this
  // update. Returns |M| of the job's snapshot.
  int swapInRelinearized() {
    bayestree::RelinearizationSnapshot<G> snap;
    bayestree::RelinearizedTree<G> job;
    async.take(&snap, &job);
    const int relinearized = static_cast<int>(snap.relinearized.size());
    adopt(baseOfJob(std::move(snap), std::move(job)), *this, /*with_queued=*/true);
    snapshot_factors = std::move(snap.factors);  // baseOfJob reads its size only
    clearSinceSnapshot();
    return relinearized;
  }

  // AsyncCatchUp::kInBackground, the update that finds the job done: a copy of the smoother's
  // state (Θ, the fixed poses, per-pose scratch; no tree) adopts the job's tree with what came
  // since the snapshot — this update's queue excepted, which this update folds into the old
  // tree — and runs one ordinary pass on it in the background. What changes from here on is
  // recorded as since the snapshot was (moved, reweighted, released), against Θ as it is now.
  void startCatchUp() {
    bayestree::RelinearizationSnapshot<G> snap;
    bayestree::RelinearizedTree<G> job;
    async.take(&snap, &job);
    catch_up_relinearized = static_cast<int>(snap.relinearized.size());
    catch_up_rounds = 1;
    launchCatchUp(baseOfJob(std::move(snap), std::move(job)));
    snapshot_factors = std::move(snap.factors);  // baseOfJob reads its size only
  }

  // AsyncRelinearizationOptions::catch_up_max_factors: a finished catch-up whose swap would
  // fold in more than that many factors hands its tree to another catch-up instead, which folds
  // them in the background too (at most catch_up_max_rounds catch-ups a job).
  bool catchUpAgain() const {
    const int arrived = factors.numFactors() + static_cast<int>(queued.size()) - catch_up_factors;
    return opt.async.catch_up_max_factors > 0 && arrived > opt.async.catch_up_max_factors &&
           catch_up_rounds < opt.async.catch_up_max_rounds && backgroundJobsAllowed();
  }
  void restartCatchUp() {
    ++catch_up_rounds;
    launchCatchUp(baseOfCatchUp());
  }

  // The catch-up on `base` (a job's tree, or a finished catch-up's): a copy of the smoother's
  // state adopts it with what came since the base's start — this update's queue excepted — and
  // one ordinary pass folds that in on the background thread.
  void launchCatchUp(SwapBase&& base) {
    SmootherOptions shadow_options = opt;
    shadow_options.relinearize = RelinearizationMode::kInline;
    shadow_options.threads = 1;
    auto shadow = std::make_unique<Impl>(shadow_options);
    const int n = numPoses();
    shadow->fixed = fixed;
    shadow->mark.assign(static_cast<size_t>(n), 0);
    shadow->updated_stamp.assign(static_cast<size_t>(n), 0);
    shadow->is_candidate.assign(static_cast<size_t>(n), 0);
    for (int v = 0; v < n; ++v) shadow->threads.addVariable();
    shadow->num_variables = num_variables;
    shadow->stamp = stamp;
    shadow->to_touch = to_touch;
    shadow->adopt(std::move(base), *this, /*with_queued=*/false);
    // A pose with no factor among the shadow's (its edges wait in this update's queue) is not
    // a variable there yet: held fixed, it is new to the tree at the swap.
    std::vector<char> has_factor(static_cast<size_t>(n), 0);
    for (const Factor<G>& e : shadow->queued)
      if (e.inlierWeight() > 0)
        for (int k = 0; k < e.arity(); ++k) has_factor[e.key(k)] = 1;
    std::vector<int> kept;
    for (int v : shadow->new_vars) {
      bool attached = has_factor[v] != 0;
      for (int f : shadow->factors.var_factors[v])
        if (shadow->factors.attached[f] || shadow->factors.factors[f].inlierWeight() > 0)
          attached = true;
      if (attached) {
        kept.push_back(v);
      } else {
        shadow->fixed[v] = 1;
        --shadow->num_variables;
      }
    }
    shadow->new_vars = std::move(kept);
    clearSinceSnapshot();
    theta_at_catch_up = theta;
    catch_up_poses = n;
    catch_up_factors = factors.numFactors();
    catch_up.start(
        std::move(shadow), [](Impl& s) { s.runPasses(StepOptions{}); }, opt.async.synchronous,
        update_count);
  }

  // The catch-up's swap: due when it is done (or, with swap_after_updates, at the update after
  // its start).
  bool catchUpSwapDue() const {
    if (opt.async.swap_after_updates > 0) return update_count >= catch_up.startedAt() + 1;
    return catch_up.done();
  }

  // The caught-up tree, with what arrived during the catch-up queued for this update (its
  // base: every pose's Θ the shadow's, the smoother's Θ then in theta_at_catch_up). Returns |M|
  // of the job's snapshot.
  int swapInCaughtUp() {
    adopt(baseOfCatchUp(), *this, /*with_queued=*/true);
    clearSinceSnapshot();
    theta_at_catch_up.clear();
    return catch_up_relinearized;
  }

  // The finished catch-up's tree as a base (its Θ for every pose; the smoother's Θ when it
  // started in theta_at_catch_up, moved out).
  SwapBase baseOfCatchUp() {
    std::unique_ptr<Impl> shadow = catch_up.take();
    SwapBase b;
    b.n = catch_up_poses;
    b.f = catch_up_factors;
    b.fixed = shadow->notInTree();
    b.theta = std::move(shadow->theta);
    b.all_relinearized = true;
    b.theta_before = std::move(theta_at_catch_up);
    b.tree = std::move(shadow->tree);
    b.factors = std::move(shadow->factors);
    b.solve = std::move(shadow->partial_solve);
    b.delta = std::move(shadow->delta);
    return b;
  }

  // One pass of IJRR 2012 Alg. 6, "One step of the iSAM2 algorithm".
  UpdateStats step(const StepOptions& pass) {
    marginals.forget();  // the tree changes below: no kept path solve holds for it
    const auto t0 = Clock::now();
    UpdateStats st;
    ++stamp;
    auto phase_start = t0;
    auto endPhase = [&phase_start](double* seconds) {
      const auto now = Clock::now();
      *seconds += std::chrono::duration<double>(now - phase_start).count();
      phase_start = now;
    };
    // Alg. 6 steps 1–2, "Add any new factors F := F ∪ F′" and "Initialize any new variables Θ′
    // and add Θ := Θ ∪ Θ′" (the poses were added by addPose, the factors queued by addFactor).
    const NewFactors added = addNewFactorsAndVariables(&st);
    pass_first_factor = added.first;
    // Alg. 6 step 3, "Fluid relinearization with Alg. 5 yields marked variables M".
    relinearizeVariables(pass, &st);
    // Alg. 4 step 2, "Relinearize all factors required to recreate top" (those of M), and the
    // new factors' first linearisation.
    listFactorsToLinearize(added.ids);
    endPhase(&st.prepare_s);
    // Extension (fold-in, docs/design.md "Loop closures by rank updates"): only factors between
    // variables already in the tree, nothing relinearised — fold them in by rank updates along
    // their paths to the root instead of Alg. 6 step 4.
    const bool folded = !pass.relinearize_all && relin.empty() && !added.restructured &&
                        st.new_variables == 0 && !added.ids.empty() && opt.rank_updates &&
                        foldInNewFactors(added.ids, &st);
    // Alg. 6 step 4, "Redo top of Bayes tree with Alg. 4 with J the union of M and all
    // variables affected by new factors".
    const bool tree_changed = folded || redoTop(pass.relinearize_all, &st);
    if (folded) maybeCheckOrderingDecay();  // the fold-ins grew separators
    for (int v : touched) mark[v] = 0;
    endPhase(&st.top_s);
    // Alg. 6 step 5, "Solve for delta Δ with Alg. 7" (and Powell's dogleg on it, as GTSAM's
    // ISAM2DoglegParams). Step 6, "Current estimate given by Θ ⊕ Δ", is estimate().
    if (pass.solve) partialStateUpdate(pass.relinearize_all, tree_changed, &st);
    endPhase(&st.solve_s);
    st.time_s = secondsSince(t0);
    return st;
  }

  struct NewFactors {
    // The factors entering the structure in this pass: the new ones of weight > 0 in the order
    // added, then those re-admitted from weight 0 (Extension, setFactorWeight).
    std::vector<int> ids;
    int first = 0;              // index of the first factor added by this pass
    bool restructured = false;  // to_touch was not empty
  };

  // Alg. 6 steps 1–2: the queued factors join `factors`; the new variables, the variables of
  // the factors entering the structure (and, Extension, to_touch: a released anchor's
  // neighbours, the factors of moved poses or reweighted) become `touched` (mark[v] = 1). A new
  // factor of weight 0 joins `factors` only: it touches nothing.
  NewFactors addNewFactorsAndVariables(UpdateStats* st) {
    NewFactors out;
    out.first = factors.numFactors();
    touched.clear();
    auto touch = [&](int v) {
      if (!fixed[v] && !mark[v]) {
        mark[v] = 1;
        touched.push_back(v);
      }
    };
    st->new_variables = static_cast<int>(new_vars.size());
    for (int v : new_vars) touch(v);
    new_vars.clear();
    out.restructured = !to_touch.empty();
    for (int v : to_touch) touch(v);
    to_touch.clear();
    auto enter = [&](int f) {
      const Factor<G>& e = factors.factors[f];
      for (int k = 0; k < e.arity(); ++k) touch(e.key(k));
      out.ids.push_back(f);
    };
    factors.reserveFor(queued.size());
    for (const Factor<G>& e : queued) {
      const int f = factors.add(e);
      if (factors.attached[f]) enter(f);
    }
    st->new_factors = static_cast<int>(queued.size());
    queued.clear();
    // A burst's queue (a map loaded in one update) is not kept at its size for the elimination
    // that follows: 0.6 GB for 1.24 million SE(2) factors.
    if (queued.capacity() > kKeptQueueCapacity) std::vector<Factor<G>>().swap(queued);
    for (int f : readmitted)
      if (factors.factors[f].inlierWeight() > 0 && !factors.attached[f]) {
        factors.attach(f);
        enter(f);
      }
    readmitted.clear();
    return out;
  }

  bool exceedsThreshold(const Vec& dx) const {
    return dx.template head<kTrans>().cwiseAbs().maxCoeff() >
               opt.relinearize_threshold_translation ||
           dx.template tail<D - kTrans>().cwiseAbs().maxCoeff() >
               opt.relinearize_threshold_rotation;
  }

  // Alg. 5 steps 1–2 into `relin` (M): "Mark variables in Δ above threshold β:
  // J = {Δ_j ∈ Δ | |Δ_j| ≥ β}" (|·|∞ on the translational and the rotational part, each against
  // its β; relinearizeAll: every variable) and "Update linearization point for marked
  // variables: Θ_J := Θ_J ⊕ Δ_J" (their Δ becomes zero).
  void relinearizeVariables(const StepOptions& pass, UpdateStats* st) {
    relin.clear();
    const int n = numPoses();
    if (pass.relinearize_all) {
      for (int v = 0; v < n; ++v)
        if (!fixed[v]) relin.push_back(v);
    } else if (pass.check_relinearization && check_all) {
      for (int v = 0; v < n; ++v)
        if (!fixed[v] && tree.clique_of[v] >= 0 && exceedsThreshold(delta[v])) relin.push_back(v);
      st->variables_checked = n;
    } else if (pass.check_relinearization) {
      // Only a variable solved since the last check can have crossed β (every other one was
      // below it then, or relinearised and solved since). In index order, as a scan of all
      // would list them (the few that crossed sorted, not every candidate).
      for (int v : relin_candidates)
        if (!fixed[v] && tree.clique_of[v] >= 0 && exceedsThreshold(delta[v])) relin.push_back(v);
      std::sort(relin.begin(), relin.end());
      st->variables_checked = static_cast<int>(relin_candidates.size());
    }
    if (pass.relinearize_all || pass.check_relinearization) {
      for (int v : relin_candidates) is_candidate[v] = 0;
      relin_candidates.clear();
      check_all = false;
    }
    // RelinearizationMode::kAsync: a large M goes to the background job; this pass goes on
    // with the old linearisation point.
    if (!pass.relinearize_all && startAsyncRelinearization(st)) relin.clear();
    for (int v : relin) {
      theta[v] = theta[v].retract(delta[v]);
      theta[v].normalize();
      delta[v].setZero();
      partial_solve.resetVariable(v);
    }
    st->variables_relinearized = static_cast<int>(relin.size());
  }

  // Alg. 4 step 2 (the factors of M; Extension: to_relinearize, from transformPoses) and the
  // new factors, each once, into `to_linearize`. With nothing relinearised they are linearised
  // at once; otherwise the top elimination linearises them beside its ordering.
  void listFactorsToLinearize(const std::vector<int>& entering) {
    to_linearize.clear();
    auto add = [&](int f) {
      if (factors.stamp[f] == stamp) return;
      factors.stamp[f] = stamp;
      to_linearize.push_back(f);
    };
    for (int v : relin)
      for (int f : factors.var_factors[v]) add(f);
    for (int f : to_relinearize) add(f);
    to_relinearize.clear();
    for (int f : entering) add(f);
    if (relin.empty()) {
      factors.linearizeAll(to_linearize, theta, &threads);
      to_linearize.clear();
    }
  }

  // Extension (fold-in): the entering factors, folded in when every one of them can be; false
  // (nothing changed) otherwise.
  bool foldInNewFactors(const std::vector<int>& entering, UpdateStats* st) {
    const int updated = fold_in.foldInAll(entering, foldInContext(), &tree);
    if (updated < 0) return false;
    st->cliques_updated += updated;
    return true;
  }

  // Alg. 4, "Updating the Bayes tree inclusive of fluid relinearization by recalculating all
  // affected cliques", for J = `touched` ∪ M (`relin`); relinearize_all: every clique. Returns
  // whether there was a top to re-eliminate.
  bool redoTop(bool relinearize_all, UpdateStats* st) {
    // Alg. 5 step 3, "Mark all cliques that involve marked variables Θ_J and all their
    // ancestors" (the ancestors are removed with them below), and the cliques where the
    // variables of the new factors are frontal.
    marked.clear();
    for (int v : touched)
      if (tree.clique_of[v] >= 0) marked.push_back(tree.clique_of[v]);
    if (relinearize_all) {
      for (int c = 0; c < static_cast<int>(tree.cliques.size()); ++c)
        if (tree.cliques[c].in_use) marked.push_back(c);
    } else {
      tree.cliquesContaining(relin, &marked);
    }
    // Alg. 4 step 1, "Remove top of Bayes tree" (its variables: the new ones first) and "Store
    // orphaned sub-trees T_O of removed cliques".
    top.variables.clear();
    top.orphans.clear();
    for (int v : touched)
      if (tree.clique_of[v] < 0) top.variables.push_back(v);
    tree.removeTop(marked, &top);
    // Extension (docs/design.md, "Never costlier than batch"): a top of more than a share of
    // the variables, or a tree whose ordering has decayed, is re-eliminated as the whole graph
    // in a fresh ordering (the touched variables still last).
    const double top_size = static_cast<double>(top.variables.size());
    const bool batch =
        !relinearize_all && !top.variables.empty() &&
        (reorder_due || top_size > opt.batch.top_share * static_cast<double>(num_variables));
    // A top of every variable is ordered afresh all the same: the decay watch measures from it.
    const bool whole_graph = top_size >= static_cast<double>(num_variables);
    if (batch) {
      marked.clear();
      for (int c = 0; c < static_cast<int>(tree.cliques.size()); ++c)
        if (tree.cliques[c].in_use) marked.push_back(c);
      for (int oc : top.orphans) tree.cliques[oc].parent = -1;  // its parent is freed
      top.orphans.clear();  // every orphan is removed with the rest
      tree.removeTop(marked, &top);
      st->batch_reeliminations = 1;
      reorder_due = false;
    }
    // Alg. 4 steps 2–6: linearise (what is left of step 2), add the orphans' cached factors,
    // re-order (constrained: the touched variables last, unless everything is re-eliminated or
    // they are more than BatchSwitchOptions::constrain_last_max), eliminate into new cliques and
    // insert the orphans back.
    const bool constrain =
        !relinearize_all && static_cast<int>(touched.size()) <= opt.batch.constrain_last_max;
    // SmootherOptions::newest_last: the newest pose joins the last group (marked for the
    // ordering only: it is not touched, so its clique is not re-eliminated for it).
    const int newest = numPoses() - 1;
    const bool newest_marked =
        constrain && opt.newest_last && newest >= 0 && !fixed[newest] && !mark[newest];
    if (newest_marked) mark[newest] = 1;
    const typename bayestree::TopElimination<G>::Input in{
        top.variables, top.orphans, constrain ? &mark : nullptr, to_linearize,
        theta,         fixed,       nestedDissectionMin(),       nestedDissectionTryFlops()};
    const auto out = top_elimination.run(in, &tree, &factors, &threads);
    st->indeterminate_cliques += out.indeterminate;
    st->cliques_on_helpers += out.on_helpers;
    st->cliques_reeliminated += out.cliques;
    st->variables_reeliminated += out.variables;
    st->reelimination_flops += out.flops;
    if (newest_marked) mark[newest] = 0;
    tree.releaseFreeStorage();                      // cliques not recycled hold no memory
    if (relinearize_all || batch || whole_graph) {  // a fresh ordering
      flops_reference = tree.flops;
      doubles_reference = tree.doubles;
      if (!relinearizationPending()) reorder_job_wanted = false;
    } else {
      maybeCheckOrderingDecay();
    }
    return !top.variables.empty();
  }

  // BatchSwitchOptions::reorder_decay: once the tree's flops or its doubles have grown by the
  // decay factor since the last comparison, compares both with those of the whole graph in a
  // fresh ordering; the next re-elimination re-orders when either exceeds decay × fresh. The
  // doubles matter on their own: an incremental ordering's cliques of few frontals under a
  // separator of thousands of dimensions cost little to factorise but hold S² doubles each (a
  // dense world revisited, docs/benchmarks.md "Memory of a dense world").
  void maybeCheckOrderingDecay() {
    const double inline_decay = opt.batch.reorder_decay;
    if (inline_decay <= 0) return;
    // With async, a job re-orders (the next update's snapshot), from the sooner decay of
    // AsyncRelinearizationOptions::reorder_decay; a decay past the inline one while a job is
    // wanted already (found again before its tree is swapped in), or no second core, re-orders
    // inline.
    const bool in_background = backgroundJobsAllowed() && opt.async.reorder_in_background;
    const double decay =
        in_background ? std::min(inline_decay, opt.async.reorder_decay) : inline_decay;
    if (tree.flops <= decay * std::max(flops_reference, kMinDecayCheckFlops) &&
        tree.doubles <= decay * std::max(doubles_reference, kMinDecayCheckDoubles))
      return;
    double fresh_doubles = 0;
    const double fresh_flops = freshOrderingCost(&fresh_doubles);
    const auto past = [&](double d) {
      return tree.flops > d * fresh_flops || tree.doubles > d * fresh_doubles;
    };
    if (in_background && !reorder_job_wanted && past(decay))
      reorder_job_wanted = true;
    else if (past(inline_decay))
      reorder_due = true;
    flops_reference = tree.flops;
    doubles_reference = tree.doubles;
  }

  // Flops of factorising every variable in the tree in a fresh ordering (the one the top
  // elimination would choose for a top of all of them, unconstrained), and in *doubles the
  // doubles its cliques would hold. O(n + m).
  double freshOrderingCost(double* doubles) {
    std::vector<int>& slot = threads.lanes[0].slot;
    std::vector<int>& vars = fresh_vars;
    vars.clear();
    for (int v = 0; v < numPoses(); ++v)
      if (!fixed[v] && tree.clique_of[v] >= 0) {
        slot[v] = static_cast<int>(vars.size());
        vars.push_back(v);
      }
    const int n = static_cast<int>(vars.size());
    fresh_rows.clear();
    for (int f = 0; f < factors.numFactors(); ++f) {
      if (!factors.attached[f]) continue;  // weight 0: not in the structure
      const Factor<G>& e = factors.factors[f];
      int keys = 0;
      for (int k = 0; k < e.arity(); ++k) keys += slot[e.key(k)] >= 0 ? 1 : 0;
      if (keys < 2) continue;
      for (int k = 0; k < e.arity(); ++k)
        if (slot[e.key(k)] >= 0) fresh_rows.add(slot[e.key(k)]);
      fresh_rows.endRow();
    }
    for (int v : vars) slot[v] = -1;
    const std::vector<int> group(static_cast<size_t>(n), 0);
    const bayestree::EliminationPlan plan = bayestree::planTop<D>(
        n, fresh_rows, group, nestedDissectionMin(), nestedDissectionTryFlops());
    const bayestree::TreeShape shape = bayestree::treeShape<D>(plan, tree.cached_factors.max_ratio);
    *doubles =
        tree.dropsCachedFactors(shape.allKeptDoubles()) ? shape.doubles() : shape.allKeptDoubles();
    return shape.flops;
  }

  // Tops of at least this many variables are ordered by nested dissection
  // (SmootherOptions::nested_dissection_min; automatic: 100 poses in 3D, never in 2D by size).
  int nestedDissectionMin() const {
    if (opt.nested_dissection_min >= 0) return opt.nested_dissection_min;
    return D == 6 ? 100 : std::numeric_limits<int>::max();
  }
  // Smaller tops whose CCOLAMD plan costs more than this many flops per variable are also
  // ordered by nested dissection, the cheaper plan kept (automatic in 2D only; planTop).
  double nestedDissectionTryFlops() const {
    return opt.nested_dissection_min < 0 && D == 3 ? kNestedDissectionTryFlops : 0.0;
  }

  // Alg. 7, "Partial state update" (full: every clique, for relinearizeAll or
  // full_backsubstitution), then the dogleg step when the tree changed.
  void partialStateUpdate(bool relinearize_all, bool tree_changed, UpdateStats* st) {
    const auto out = partial_solve.run(&tree, relinearize_all || opt.full_backsubstitution,
                                       opt.wildfire_threshold, entriesOf(opt.solve_budget_mb),
                                       opt.dogleg ? nullptr : &delta, &threads);
    st->cliques_solved += out.solved;
    st->cliques_deferred = out.deferred;
    st->cliques_on_helpers += out.on_helpers;
    noteSolved();
    if (opt.dogleg && tree_changed) {
      doglegStep();  // sets Δ everywhere
      updated_all = true;
      check_all = true;
    }
  }

  // A budget in MB as entries of [L; Sᵀ] (0: none).
  static double entriesOf(double budget_mb) { return budget_mb * 1e6 / sizeof(double); }

  // solveDeferred(): the backlog solved whole (a run without a budget solves it).
  UpdateStats solveDeferred(double budget_mb) {
    UpdateStats st;
    if (tree.num_deferred == 0) return st;
    if (!(budget_mb >= 0 && std::isfinite(budget_mb)))
      throw std::invalid_argument("IncrementalSmoother::solveDeferred: bad budget_mb " +
                                  std::to_string(budget_mb) + " (must be finite and ≥ 0)");
    const auto t0 = Clock::now();
    beginUpdated();
    const auto out = partial_solve.run(&tree, false, opt.wildfire_threshold, entriesOf(budget_mb),
                                       &delta, &threads);
    st.cliques_solved = out.solved;
    st.cliques_deferred = out.deferred;
    noteSolved();
    finishUpdated();
    st.solve_s = st.time_s = secondsSince(t0);
    return st;
  }

  // Σ w eᵀΩe at θ ⊞ x for every pose (w = 1 for every factor unless `weighted`): the dogleg and
  // relinearizeAll judge steps by the weighted objective, the one the linear system models.
  double objectiveAt(const std::vector<Vec>& x, bool weighted = true) const {
    std::vector<G> poses(theta.size());
    for (size_t v = 0; v < theta.size(); ++v)
      poses[v] = fixed[v] ? theta[v] : theta[v].retract(x[v]);
    double f = 0;
    for (const Factor<G>& e : factors.factors)
      f += weighted ? e.inlierWeight() * e.cost(poses) : e.cost(poses);
    return f;
  }

  // Powell's dogleg step on the Bayes tree (bayestree/dogleg_step.h) into Δ.
  void doglegStep() {
    delta = bayestree::doglegStep<D>(tree.cliques, partial_solve.delta_newton, &dogleg_radius,
                                     opt.dogleg_min_radius,
                                     [&](const std::vector<Vec>& x) { return objectiveAt(x); });
  }

  // Passes of Alg. 6 with every variable relinearised and the whole tree re-eliminated, until F
  // settles (Gauss–Newton steps halved while F rises).
  UpdateStats relinearizeAll(const CancellationToken* cancel) {
    const auto t0 = Clock::now();
    UpdateStats total;
    replaced = bayestree::RelinearizedTree<G>();
    std::vector<Factor<G>>().swap(snapshot_factors);
    if (relinearizationPending()) {  // everything is relinearised below: the job is not needed
      async.abandon();
      catch_up.abandon();
      theta_at_catch_up.clear();
      clearSinceSnapshot();
      check_all = true;  // the snapshot's check consumed its candidates
    }
    if (!queued.empty() || !new_vars.empty()) accumulate(&total, update());
    beginUpdated();
    updated_all = true;  // every Δ is set (and may be halved) below
    double F_prev = objectiveAt(delta);
    StepOptions everything;
    everything.relinearize_all = true;
    for (int it = 0; it < opt.finalize_max_iterations; ++it) {
      if (cancel != nullptr && cancel->cancelled()) {
        total.cancelled = true;
        break;
      }
      ++total.refine_iterations;
      accumulate(&total, step(everything));
      double F_new = objectiveAt(delta);
      if (!opt.dogleg && F_new > F_prev) {
        // Gauss–Newton overshoots: halve the step until F decreases (or give it up).
        std::vector<Vec> step_taken = partial_solve.delta_newton;
        double scale = 1.0;
        for (int k = 0; k < 10 && F_new > F_prev; ++k) {
          scale *= 0.5;
          for (size_t v = 0; v < step_taken.size(); ++v) delta[v] = scale * step_taken[v];
          F_new = objectiveAt(delta);
        }
        if (F_new > F_prev) {
          for (Vec& v : delta) v.setZero();
          F_new = objectiveAt(delta);
        }
      }
      const double change = std::abs(F_prev - F_new) / std::max(F_prev, 1e-300);
      F_prev = F_new;
      if (change < opt.finalize_relative_tolerance) break;
    }
    check_all = true;  // the halving set Δ outside the solve
    finishUpdated();
    total.time_s = secondsSince(t0);
    return total;
  }

  void checkInvariants() const {
    tree.checkInvariants(factors.factors, factors.attached, fixed, [&](int v) {
      return mark[v] || std::find(new_vars.begin(), new_vars.end(), v) != new_vars.end();
    });
  }
};

template <class G>
IncrementalSmoother<G>::IncrementalSmoother(SmootherOptions options)
    : impl_(std::make_unique<Impl>(options)) {
  useOneBlasThread();  // the dense clique kernels call LAPACK/BLAS
}
template <class G>
IncrementalSmoother<G>::~IncrementalSmoother() = default;
template <class G>
IncrementalSmoother<G>::IncrementalSmoother(const IncrementalSmoother& other)
    : impl_(std::make_unique<Impl>(*other.impl_)) {}
template <class G>
IncrementalSmoother<G>& IncrementalSmoother<G>::operator=(const IncrementalSmoother& other) {
  if (this != &other) impl_ = std::make_unique<Impl>(*other.impl_);
  return *this;
}
template <class G>
IncrementalSmoother<G>::IncrementalSmoother(IncrementalSmoother&&) noexcept = default;
template <class G>
IncrementalSmoother<G>& IncrementalSmoother<G>::operator=(IncrementalSmoother&&) noexcept = default;

template <class G>
int IncrementalSmoother<G>::addFixedPose(const G& value) {
  return impl_->addPose(value, true);
}
template <class G>
int IncrementalSmoother<G>::addPose(const G& initial) {
  return impl_->addPose(initial, false);
}
template <class G>
void IncrementalSmoother<G>::addFactor(const Factor<G>& factor) {
  impl_->addFactor(factor);
}
template <class G>
void IncrementalSmoother<G>::releaseFixedPose(int index) {
  impl_->releaseFixedPose(index);
}
template <class G>
void IncrementalSmoother<G>::transformPoses(const std::vector<int>& indices, const G& T) {
  impl_->transformPoses(indices, T);
}
template <class G>
void IncrementalSmoother<G>::setFactorWeight(int index, double w) {
  impl_->setFactorWeight(index, w);
}
template <class G>
UpdateStats IncrementalSmoother<G>::update() {
  return impl_->update();
}
template <class G>
UpdateStats IncrementalSmoother<G>::relinearizeAll(const CancellationToken* cancel) {
  return impl_->relinearizeAll(cancel);
}
template <class G>
UpdateStats IncrementalSmoother<G>::solveDeferred(double budget_mb) {
  return impl_->solveDeferred(budget_mb);
}
template <class G>
int IncrementalSmoother<G>::cliquesDeferred() const {
  return impl_->tree.num_deferred;
}
template <class G>
bool IncrementalSmoother<G>::relinearizationPending() const {
  return impl_->relinearizationPending();
}
template <class G>
void IncrementalSmoother<G>::setSecondCoreBusy(bool busy) {
  impl_->second_core_busy = busy;
}
template <class G>
std::vector<G> IncrementalSmoother<G>::estimate() const {
  std::vector<G> out(impl_->theta.size());
  for (size_t v = 0; v < out.size(); ++v) out[v] = estimate(static_cast<int>(v));
  return out;
}
template <class G>
G IncrementalSmoother<G>::estimate(int index) const {
  if (index < 0 || index >= impl_->numPoses())
    throw std::out_of_range("IncrementalSmoother::estimate: index " + std::to_string(index) +
                            " out of range");
  if (impl_->fixed[index]) return impl_->theta[index];
  return impl_->theta[index].retract(impl_->delta[index]);
}
template <class G>
const std::vector<int>& IncrementalSmoother<G>::updatedPoses() const {
  return impl_->updatedInOrder();
}
template <class G>
double IncrementalSmoother<G>::factorizationFlops() const {
  return impl_->tree.flops;
}
template <class G>
double IncrementalSmoother<G>::factorizationDoubles() const {
  return impl_->tree.doubles;
}
template <class G>
const std::vector<G>& IncrementalSmoother<G>::linearizationPoint() const {
  return impl_->theta;
}
template <class G>
const std::vector<typename G::Tangent>& IncrementalSmoother<G>::delta() const {
  return impl_->delta;
}
template <class G>
double IncrementalSmoother<G>::objective() const {
  return impl_->objectiveAt(impl_->delta, false);
}
template <class G>
double IncrementalSmoother<G>::weightedObjective() const {
  return impl_->objectiveAt(impl_->delta, true);
}
template <class G>
void IncrementalSmoother<G>::checkInvariants() const {
  impl_->checkInvariants();
}
template <class G>
int IncrementalSmoother<G>::numCliques() const {
  return impl_->tree.num_cliques;
}
template <class G>
TreeMemory IncrementalSmoother<G>::memory() const {
  return impl_->memory();
}

template <class G>
int IncrementalSmoother<G>::numPoses() const {
  return impl_->numPoses();
}
template <class G>
int IncrementalSmoother<G>::numFactors() const {
  return impl_->factors.numFactors();
}
template <class G>
bool IncrementalSmoother<G>::isFixed(int index) const {
  return index >= 0 && index < impl_->numPoses() && impl_->fixed[index];
}
template <class G>
const std::vector<Factor<G>>& IncrementalSmoother<G>::factors() const {
  return impl_->factors.factors;
}
template <class G>
const SmootherOptions& IncrementalSmoother<G>::options() const {
  return impl_->opt;
}

template <class G>
auto IncrementalSmoother<G>::marginalCovariance(int index) const
    -> Eigen::Matrix<double, kDoF, kDoF> {
  return jointMarginalCovariance(index, index).template topLeftCorner<kDoF, kDoF>();
}
template <class G>
auto IncrementalSmoother<G>::jointMarginalCovariance(int a, int b) const
    -> Eigen::Matrix<double, 2 * kDoF, 2 * kDoF> {
  const Impl& m = *impl_;
  for (int v : {a, b}) {
    if (v < 0 || v >= m.numPoses())
      throw std::out_of_range("IncrementalSmoother: covariance of pose index " + std::to_string(v) +
                              ": out of range (" + std::to_string(m.numPoses()) + " poses)");
    if (!m.fixed[v] && m.tree.clique_of[v] < 0)
      throw std::logic_error("IncrementalSmoother: covariance of pose index " + std::to_string(v) +
                             ": not in the Bayes tree yet (call update() first)");
  }
  if (a == b) {
    Eigen::Matrix<double, 2 * kDoF, 2 * kDoF> out =
        Eigen::Matrix<double, 2 * kDoF, 2 * kDoF>::Zero();
    if (!m.fixed[a]) {
      const Eigen::Matrix<double, kDoF, kDoF> s = m.marginals.marginal(m.tree, a);
      out << s, s, s, s;
    }
    return out;
  }
  return m.marginals.joint(m.tree, a, b);
}

template <class G>
auto IncrementalSmoother<G>::predictionCovariance(int a,
                                                  const Eigen::Matrix<double, kDoF, kDoF>& A_a,
                                                  int b,
                                                  const Eigen::Matrix<double, kDoF, kDoF>& A_b,
                                                  PredictionPaths paths) const
    -> Eigen::Matrix<double, kDoF, kDoF> {
  const Impl& m = *impl_;
  m.checkPredictionPoses(a, b);
  if (paths == PredictionPaths::kOnce)
    return bayestree::TreeMarginals<kDoF>::predicted(m.tree, {a, b}, {A_a, A_b});
  // A Σ Aᵀ = [A_a A_b] [[Σ_aa, Σ_ab], [Σ_ba, Σ_bb]] [A_a A_b]ᵀ (a fixed pose: zero rows; a = b:
  // every block Σ_aa).
  Eigen::Matrix<double, kDoF, 2 * kDoF> A;
  A << A_a, A_b;
  return A * m.marginals.jointKept(m.tree, a, b) * A.transpose();
}

template <class G>
auto IncrementalSmoother<G>::predictionCovarianceBound(
    int a, const Eigen::Matrix<double, kDoF, kDoF>& A_a, int b,
    const Eigen::Matrix<double, kDoF, kDoF>& A_b) const -> Eigen::Matrix<double, kDoF, kDoF> {
  const Impl& m = *impl_;
  m.checkPredictionPoses(a, b);
  Eigen::Matrix<double, kDoF, kDoF> out = Eigen::Matrix<double, kDoF, kDoF>::Zero();
  for (const auto& [v, A_v] : {std::pair{a, &A_a}, std::pair{b, &A_b}})
    if (!m.fixed[v]) out.noalias() += *A_v * m.marginals.marginalKept(m.tree, v) * A_v->transpose();
  return 2 * out;
}

template <class G>
int IncrementalSmoother<G>::keepSharedCliqueJoints(
    const std::vector<std::pair<int, int>>& pose_pairs) const {
  // The smoother's lanes are idle between updates, and no other const call uses them; two
  // calls of this one are serialised on the marginals' mutex.
  Impl& m = *impl_;
  return m.marginals.keepSharedCliqueJoints(m.tree, pose_pairs, &m.threads.workers);
}

template <class G>
auto IncrementalSmoother<G>::marginalCovariances() const
    -> std::vector<Eigen::Matrix<double, kDoF, kDoF>> {
  const Impl& m = *impl_;
  for (int v = 0; v < m.numPoses(); ++v)
    if (!m.fixed[v] && m.tree.clique_of[v] < 0)
      throw std::logic_error("IncrementalSmoother: covariance of pose index " + std::to_string(v) +
                             ": not in the Bayes tree yet (call update() first)");
  std::vector<Eigen::Matrix<double, kDoF, kDoF>> out(m.numPoses(),
                                                     Eigen::Matrix<double, kDoF, kDoF>::Zero());
  bayestree::TreeMarginals<kDoF>::all(m.tree, &out);
  return out;
}

template class IncrementalSmoother<SE2>;
template class IncrementalSmoother<SE3>;

}  // namespace arbor
