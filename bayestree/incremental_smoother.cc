// The smoother: IJRR 2012 Alg. 6 (one step of iSAM2) over the units of bayestree/ — the Bayes tree
// (bayes_tree.h), the linearised factors (linear_factors.h), the top elimination
// (top_elimination.h), the fold-in (fold_in.h, our extension), the partial state update
// (partial_solve.h), Alg. 5's check (relinearization_check.h), the re-ordering decay watch
// (ordering_decay.h), the asynchronous relinearisation's jobs and swap (relinearization_jobs.h,
// relinearization_swap.h), and the updated poses (updated_poses.h), with the threads they share
// (update_threads.h). Numbers are those of Kaess et al., "iSAM2: Incremental smoothing and mapping
// using the Bayes tree", IJRR 31(2), 2012 (the ICRA 2011 paper numbers its listings differently):
// Alg. 3 the Bayes-tree update with new factors, Alg. 4 the same with fluid relinearisation, Alg. 5
// fluid relinearisation, Alg. 6 one step of iSAM2, Alg. 7 the partial state update. Steps marked
// "Extension" are ours (docs/design.md, "The update, step by step").
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

#include "arbor_slam/bayestree/bayes_tree.h"
#include "arbor_slam/bayestree/dogleg_step.h"
#include "arbor_slam/bayestree/fold_in.h"
#include "arbor_slam/bayestree/linear_factors.h"
#include "arbor_slam/bayestree/marginals.h"
#include "arbor_slam/bayestree/ordering_decay.h"
#include "arbor_slam/bayestree/partial_solve.h"
#include "arbor_slam/bayestree/relinearization_check.h"
#include "arbor_slam/bayestree/relinearization_jobs.h"
#include "arbor_slam/bayestree/relinearization_swap.h"
#include "arbor_slam/bayestree/top_elimination.h"
#include "arbor_slam/bayestree/update_threads.h"
#include "arbor_slam/bayestree/updated_poses.h"
#include "arbor_slam/core/blas_threads.h"
#include "arbor_slam/core/elapsed.h"
#include "arbor_slam/core/factor_error.h"
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

// The arguments of the smoother's calls, checked before anything changes.
template <class G>
void checkNewFactor(const Factor<G>& f, int num_poses) {
  std::string where = "IncrementalSmoother::addFactor(" + f.name();
  for (int k = 0; k < f.arity(); ++k) where += (k ? ", " : " ") + std::to_string(f.key(k));
  where += "): ";
  for (int k = 0; k < f.arity(); ++k)
    if (f.key(k) < 0 || f.key(k) >= num_poses)
      throw std::invalid_argument(where + "pose index out of range (" + std::to_string(num_poses) +
                                  " poses)");
  if (f.arity() == 2 && f.key(0) == f.key(1)) throw std::invalid_argument(where + "self-loop");
  if (!f.isFinite()) throw std::invalid_argument(where + "measurement or information not finite");
  const std::string problem =
      std::visit([](const auto& x) { return informationProblem(x.information); }, f.variant());
  if (!problem.empty()) throw std::invalid_argument(where + "information matrix " + problem);
}

template <class G>
void checkMove(const std::vector<int>& poses, const G& T, int num_poses) {
  if (!allFinite(T))
    throw std::invalid_argument("IncrementalSmoother::transformPoses: transform not finite");
  for (int v : poses)
    if (v < 0 || v >= num_poses)
      throw std::invalid_argument("IncrementalSmoother::transformPoses: index " +
                                  std::to_string(v) + " out of range");
}

void checkWeight(int f, double w, int num_factors) {
  if (f < 0 || f >= num_factors)
    throw std::invalid_argument("IncrementalSmoother::setFactorWeight: factor " +
                                std::to_string(f) + " out of range (" +
                                std::to_string(num_factors) + " factors, queued included)");
  if (!(w >= 0 && w <= 1))
    throw std::invalid_argument("IncrementalSmoother::setFactorWeight(" + std::to_string(f) +
                                "): weight " + std::to_string(w) + " not in [0, 1]");
}

// predictionCovariance's poses: in range and in the tree (or fixed).
void checkPredictionPoseIndices(int a, int b, const std::vector<char>& fixed,
                                const std::vector<int>& clique_of) {
  const int num_poses = static_cast<int>(fixed.size());
  for (int v : {a, b}) {
    if (v < 0 || v >= num_poses)
      throw std::out_of_range("IncrementalSmoother: prediction covariance on pose index " +
                              std::to_string(v) + ": out of range (" + std::to_string(num_poses) +
                              " poses)");
    if (!fixed[v] && clique_of[v] < 0)
      throw std::logic_error("IncrementalSmoother: prediction covariance on pose index " +
                             std::to_string(v) +
                             ": not in the Bayes tree yet (call update() first)");
  }
}

// 2D tops (SmootherOptions::nested_dissection_min automatic) whose CCOLAMD plan costs more than
// this many flops per variable are ordered by nested dissection too, the cheaper plan kept. The
// shared 2D sets stay below it (M3500 and manhattan whole: 2·10³ a variable, where nested
// dissection costs 14–30% more in total), the generated 50,000-pose world's tops pass it (its
// whole graph: 1.1·10⁵ a variable under CCOLAMD, 3.4·10⁴ under nested dissection;
// docs/benchmarks.md, "Nested dissection for heavy 2D tops").
constexpr double kNestedDissectionTryFlops = 2e4;
// The queue of factors keeps its storage between updates up to this many factors.
constexpr size_t kKeptQueueCapacity = 4096;

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
  bayestree::UpdatedPoses updated;  // updatedPoses()
  // Alg. 5's check: the variables solved since the last one (bayestree/relinearization_check.h).
  bayestree::RelinearizationCheck<G> relinearization_check;
  // The batch switch (BatchSwitchOptions): the variables (not fixed), and the watch of the
  // ordering's decay (bayestree/ordering_decay.h).
  int num_variables = 0;
  bayestree::OrderingDecay<G> decay;
  // RelinearizationMode::kAsync (bayestree/relinearization_jobs.h): the job or catch-up in
  // flight, what changed since its snapshot, the buffers kept between jobs.
  bayestree::RelinearizationJobs<G, Impl> async;
  int pass_first_factor = 0;  // the first factor of the current pass (the snapshot's end)
  // Factors of your own among `factors`: their evaluation can fail, so an update with one in
  // the graph or the queue is guarded (docs/library.md, "When an update throws"): each pass
  // linearises them first, all or none (before anything of the tree changes), and a failure
  // undoes the update from `journal`. Pose-only graphs take none of this.
  int num_custom = 0;
  std::vector<typename bayestree::LinearizedFactors<G>::LinearFactor> staged;
  std::vector<int> custom_to_linearize;
  // What a guarded update (or relinearizeAll iteration) changed that its undo restores; O(the
  // queue, the relinearised variables and the last update's poses).
  struct Relinearized {
    int v;
    G theta;
    Vec delta, delta_newton, delta_seen;
  };
  struct Journal {
    bool active = false;
    bool tree_changed = false;  // past the point of no undo (a factor's failure cannot get here)
    bool async_started = false;
    int first_factor = 0, update_count = 0, num_custom = 0;
    std::vector<Factor<G>> queued;
    std::vector<int> new_vars, to_touch, to_relinearize, readmitted;
    std::vector<Relinearized> relinearized;
    bayestree::UpdatedPoses::Saved updated;
    bool updated_saved = false;
  } journal;

  explicit Impl(const SmootherOptions& o)
      : opt(o), threads(threadCount(o.threads)), dogleg_radius(o.dogleg_initial_radius) {
    validate(o);
    tree.cached_factors = o.cached_factors;
  }

  int numPoses() const { return static_cast<int>(theta.size()); }
  void checkPredictionPoses(int a, int b) const {
    checkPredictionPoseIndices(a, b, fixed, tree.clique_of);
  }
  // A relinearisation job or its catch-up in flight (no check runs; changes are recorded).
  bool relinearizationPending() const { return async.pending(); }
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
    updated.addPose();
    relinearization_check.addPose();
    if (!is_fixed) {
      new_vars.push_back(index);
      ++num_variables;
    }
    return index;
  }

  void addFactor(const Factor<G>& f) {
    checkNewFactor(f, numPoses());
    queued.push_back(f);
  }

  void discardQueuedFactor(int index) {
    const int k = index - factors.numFactors();
    if (k < 0 || k >= static_cast<int>(queued.size()))
      throw std::invalid_argument("IncrementalSmoother::discardQueuedFactor: no factor " +
                                  std::to_string(index) + " queued (" +
                                  std::to_string(queued.size()) + " queued from " +
                                  std::to_string(factors.numFactors()) + ")");
    queued.erase(queued.begin() + k);
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
    if (relinearizationPending()) async.since.released.push_back(v);
    for (int f : factors.var_factors[v]) {
      const Factor<G>& e = factors.factors[f];
      for (int k = 0; k < e.arity(); ++k)
        if (e.key(k) != v && !fixed[e.key(k)]) to_touch.push_back(e.key(k));
    }
  }

  // Extension (the online layer's components): θ_v ← T θ_v; the factors not invariant under
  // the move are relinearised and their cliques re-eliminated by the next update.
  void transformPoses(const std::vector<int>& poses, const G& T) {
    checkMove(poses, T, numPoses());
    for (int v : poses) mark[v] = 1;
    updated.moved(poses);
    if (relinearizationPending())
      async.since.moved.insert(async.since.moved.end(), poses.begin(), poses.end());
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
    checkWeight(f, w, added + static_cast<int>(queued.size()));
    if (f >= added) {
      queued[static_cast<size_t>(f - added)].setInlierWeight(w);
      return;
    }
    Factor<G>& e = factors.factors[f];
    if (e.inlierWeight() == w) return;
    e.setInlierWeight(w);
    if (relinearizationPending()) async.since.reweighted.push_back(f);
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

  // After a solve: its variables are updated and are the next relinearisation check's
  // candidates.
  void noteSolved() {
    for (int v : partial_solve.solved_variables) {
      updated.note(v);
      relinearization_check.solved(v);
    }
  }

  // One update, in three layers. (1) Extension, async: a tree relinearised in the background
  // is swapped in, or handed to a catch-up (swapLayer). (2) Extension, split: when new poses
  // arrive with factors a rank update could take (a pose with its loop closures, --step pose),
  // the factors that bring the new poses into the tree go first (a pass without its solve) and
  // the others are folded in by a second pass; the linear system, hence the step, is that of
  // one update with all of them (runPasses). (3) The paper's pass, Alg. 6 (step).
  UpdateStats update() {
    if (!mayFail()) return applyUpdate();
    journal.updated = updated.save();
    journal.updated_saved = true;
    journal.update_count = update_count;
    try {
      UpdateStats st = applyUpdate();
      endJournal();
      return st;
    } catch (...) {
      rollBack();
      throw;
    }
  }

  // Whether a factor's evaluation can fail in the next update: a factor of your own in the
  // graph or queued (O(queue) when none is in the graph).
  bool mayFail() const {
    if (num_custom > 0) return true;
    for (const Factor<G>& f : queued)
      if (f.custom()) return true;
    return false;
  }

  // The journal starts: what the undo of a guarded pass restores, as it is now.
  void beginJournal() {
    journal.active = true;
    journal.tree_changed = false;
    journal.async_started = false;
    journal.first_factor = factors.numFactors();
    journal.num_custom = num_custom;
    journal.queued = queued;
    journal.new_vars = new_vars;
    journal.to_touch = to_touch;
    journal.to_relinearize = to_relinearize;
    journal.readmitted = readmitted;
    journal.relinearized.clear();
  }
  void endJournal() {
    journal.active = false;
    journal.updated_saved = false;
    journal.queued.clear();
    journal.relinearized.clear();
  }

  // Undoes a guarded update (or relinearizeAll iteration) that threw before its tree changed:
  // the smoother is as it was before it, its queue included.
  void rollBack() {
    if (!journal.active || journal.tree_changed) {  // not a factor's failure: nothing to undo by
      endJournal();
      return;
    }
    for (int v : touched) mark[v] = 0;
    if (numPoses() > 0) mark[numPoses() - 1] = 0;
    for (auto it = journal.relinearized.rbegin(); it != journal.relinearized.rend(); ++it) {
      theta[it->v] = it->theta;
      delta[it->v] = it->delta;
      partial_solve.delta_newton[it->v] = it->delta_newton;
      partial_solve.delta_seen[it->v] = it->delta_seen;
    }
    // A check that ran consumed its candidates; scanning every variable marks the same ones.
    relinearization_check.scanAll();
    if (journal.async_started) async.abandon();
    for (int f : journal.readmitted)
      if (f < journal.first_factor) factors.detach(f);
    factors.truncate(journal.first_factor);
    num_custom = journal.num_custom;
    queued = std::move(journal.queued);
    new_vars = std::move(journal.new_vars);
    to_touch = std::move(journal.to_touch);
    to_relinearize = std::move(journal.to_relinearize);
    readmitted = std::move(journal.readmitted);
    if (journal.updated_saved) {
      update_count = journal.update_count;
      updated.restore(std::move(journal.updated));
    } else {
      updated.finish(fixed);  // a swapped-in tree, or relinearizeAll: its list stands
    }
    endJournal();
  }

  UpdateStats applyUpdate() {
    updated.begin();
    ++update_count;
    const auto t_swap = Clock::now();
    bool caught_up = false;
    const int swapped = swapLayer(&caught_up);
    const double swap_s = swapped >= 0 || caught_up ? secondsSince(t_swap) : 0.0;
    // A guarded update's undo starts here: a tree swapped in above stays (a complete change).
    if (journal.updated_saved) {
      if (swapped >= 0 || caught_up) journal.updated_saved = false;
      beginJournal();
    }
    // While a job or catch-up is in flight, no check runs (its variables wait for the swap).
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
    updated.finish(fixed);
    return st;
  }

  UpdateStats runPasses(const StepOptions& pass) {
    const auto weighted = [](const Factor<G>& e) { return e.inlierWeight() > 0; };
    // A guarded update is one pass, so that its undo is that of one pass.
    if (!opt.rank_updates || opt.dogleg || new_vars.empty() ||
        std::count_if(queued.begin(), queued.end(), weighted) < 2 || !to_touch.empty() ||
        journal.active)
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
    return opt.relinearize == RelinearizationMode::kAsync && !async.second_core_busy;
  }

  // At a check that marked M (`relin`, not yet applied): when M is large (or the decay watch
  // wants a re-ordering), the second core free and no job in flight, snapshots what the
  // re-elimination reads — the factors of the tree (those before this pass's), Θ with
  // Θ_M := Θ_M ⊕ Δ_M, the poses held fixed (the gauge poses and those not in the tree yet) — and
  // starts the background job. O(n + m) copies.
  bool startAsyncRelinearization(UpdateStats* st) {
    if (!backgroundJobsAllowed() || relinearizationPending() ||
        (static_cast<int>(relin.size()) < opt.async.min_variables && !decay.jobWanted()))
      return false;
    bayestree::RelinearizationSnapshot<G> s;
    s.theta = theta;
    s.fixed = notInTree();
    s.relinearized = relin;
    s.update = update_count;
    s.nested_dissection_min = nestedDissectionMin();
    s.nested_dissection_try_flops = nestedDissectionTryFlops();
    s.cached_factors = opt.cached_factors;
    s.iterations = opt.async.job_iterations;
    s.relative_tolerance = opt.finalize_relative_tolerance;
    async.startJob(std::move(s), factors.factors, pass_first_factor, delta, opt.async.synchronous);
    st->async_started = 1;
    return true;
  }

  // What the swap reads of this smoother (bayestree/relinearization_swap.h).
  bayestree::SwapSource<G> swapSource(bool with_queued) const {
    return {theta, fixed, factors, with_queued ? &queued : nullptr, to_relinearize, async.since};
  }

  // Installs a rebased state: the tree, Θ, Δ and linearisations become the base's (the old ones
  // wait in async.replaced for the next job's thread to free), and the next pass folds in what
  // came since. Every Δ is the base's: the next check scans every variable; the ordering is
  // fresh.
  void install(bayestree::Rebased<G>&& r) {
    async.replaced.tree = std::move(tree);
    async.replaced.factors = std::move(factors);
    async.replaced.solve = std::move(partial_solve);
    async.replaced.delta = std::move(delta);
    theta = std::move(r.theta);
    tree = std::move(r.tree);
    factors = std::move(r.factors);
    partial_solve = std::move(r.solve);
    delta = std::move(r.delta);
    queued = std::move(r.queued);
    to_relinearize = std::move(r.to_relinearize);
    to_touch.insert(to_touch.end(), r.touch.begin(), r.touch.end());
    readmitted.insert(readmitted.end(), r.readmitted.begin(), r.readmitted.end());
    new_vars = std::move(r.new_vars);
    relinearization_check.consume();
    relinearization_check.scanAll();
    decay.adoptedFresh(tree);
    updated.noteAll();
    marginals = bayestree::TreeMarginals<D>();
    num_custom = static_cast<int>(std::count_if(factors.factors.begin(), factors.factors.end(),
                                                [](const Factor<G>& f) { return f.custom(); }));
  }

  // The swap of a base (the job's tree, or the caught-up one), everything since its start and
  // this update's queue queued for this update.
  void swapIn(bayestree::SwapBase<G>&& base) {
    install(bayestree::rebase(std::move(base), swapSource(/*with_queued=*/true)));
    async.since.clear();
  }

  // The catch-up on `base` (a job's tree, or a finished catch-up's): a copy of the smoother's
  // state (Θ, the fixed poses, per-pose scratch; no tree) takes it with what came since the
  // base's start — this update's queue excepted, which this update folds into the old tree —
  // and one ordinary pass folds that in on the background thread.
  void launchCatchUp(bayestree::SwapBase<G>&& base, int relinearized, bool first_round) {
    SmootherOptions shadow_options = opt;
    shadow_options.relinearize = RelinearizationMode::kInline;
    shadow_options.threads = 1;
    auto shadow = std::make_unique<Impl>(shadow_options);
    const int n = numPoses();
    shadow->fixed = fixed;
    shadow->mark.assign(static_cast<size_t>(n), 0);
    for (int v = 0; v < n; ++v) shadow->updated.addPose();
    for (int v = 0; v < n; ++v) shadow->relinearization_check.addPose();
    for (int v = 0; v < n; ++v) shadow->threads.addVariable();
    shadow->num_variables = num_variables;
    shadow->stamp = stamp;
    shadow->to_touch = to_touch;
    bayestree::Rebased<G> r = bayestree::rebase(std::move(base), swapSource(false));
    for (int v : bayestree::holdUnattached(&r)) {
      shadow->fixed[v] = 1;
      --shadow->num_variables;
    }
    shadow->install(std::move(r));
    async.startCatchUp(
        std::move(shadow), [](Impl& s) { s.runPasses(StepOptions{}); }, theta, factors.numFactors(),
        relinearized, first_round, opt.async.synchronous, update_count);
  }

  // The finished catch-up's tree as a base (its Θ for every pose).
  bayestree::SwapBase<G> baseOfCatchUp() {
    bayestree::SwapBase<G> b;
    std::unique_ptr<Impl> shadow = async.takeCatchUp(&b);
    b.fixed = shadow->notInTree();
    b.theta = std::move(shadow->theta);
    b.tree = std::move(shadow->tree);
    b.factors = std::move(shadow->factors);
    b.solve = std::move(shadow->partial_solve);
    b.delta = std::move(shadow->delta);
    return b;
  }

  // Layer 1 of an update: a finished job's tree is swapped in (AsyncCatchUp::kOnSwap) or handed
  // to a catch-up (kInBackground); a finished catch-up's tree is swapped in, or handed to
  // another catch-up when too much arrived meanwhile (catch_up_max_factors). Returns |M| of the
  // job's snapshot when a tree was swapped in (else −1); *caught_up: a catch-up started.
  int swapLayer(bool* caught_up) {
    int relinearized = -1;
    if (async.jobSwapDue(update_count, opt.async)) {
      bayestree::SwapBase<G> base = async.takeJob(&relinearized);
      if (opt.async.catch_up == AsyncCatchUp::kInBackground) {
        launchCatchUp(std::move(base), relinearized, /*first_round=*/true);
        *caught_up = true;
        return -1;
      }
      swapIn(std::move(base));
      return relinearized;
    }
    if (async.catchUpSwapDue(update_count, opt.async)) {
      const int factors_now = factors.numFactors() + static_cast<int>(queued.size());
      if (async.catchUpAgain(factors_now, opt.async, backgroundJobsAllowed())) {
        launchCatchUp(baseOfCatchUp(), 0, /*first_round=*/false);
        *caught_up = true;
        return -1;
      }
      relinearized = async.catchUpRelinearized();
      swapIn(baseOfCatchUp());
    }
    return relinearized;
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
    journal.tree_changed = journal.active;  // nothing below can fail for a factor of your own
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
      if (e.custom()) ++num_custom;
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

  // Alg. 5 steps 1–2 into `relin` (M): "Mark variables in Δ above threshold β"
  // (bayestree/relinearization_check.h; relinearizeAll: every variable) and "Update
  // linearization point for marked variables: Θ_J := Θ_J ⊕ Δ_J" (their Δ becomes zero).
  void relinearizeVariables(const StepOptions& pass, UpdateStats* st) {
    relin.clear();
    if (pass.relinearize_all) {
      for (int v = 0; v < numPoses(); ++v)
        if (!fixed[v]) relin.push_back(v);
      relinearization_check.consume();
    } else if (pass.check_relinearization) {
      st->variables_checked = relinearization_check.mark(
          delta, fixed, tree.clique_of, opt.relinearize_threshold_translation,
          opt.relinearize_threshold_rotation, &relin);
    }
    // RelinearizationMode::kAsync: a large M goes to the background job; this pass goes on
    // with the old linearisation point.
    if (!pass.relinearize_all && startAsyncRelinearization(st)) {
      relin.clear();
      journal.async_started = journal.active;
    }
    if (journal.active)
      for (int v : relin)
        journal.relinearized.push_back(
            {v, theta[v], delta[v], partial_solve.delta_newton[v], partial_solve.delta_seen[v]});
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
    // Factors of your own first, all or none, before anything of the tree changes: a failure
    // throws (FactorError) with every linearisation as it was (the guarded update's undo).
    if (num_custom > 0) {
      custom_to_linearize.clear();
      const auto own = [&](int f) { return factors.factors[f].custom() != nullptr; };
      for (int f : to_linearize)
        if (own(f)) custom_to_linearize.push_back(f);
      if (!custom_to_linearize.empty()) {
        factors.linearizeAllOrNone(custom_to_linearize, theta, &threads, &staged);
        to_linearize.erase(std::remove_if(to_linearize.begin(), to_linearize.end(), own),
                           to_linearize.end());
      }
    }
    if (relin.empty()) {
      factors.linearizeAll(to_linearize, theta, &threads);
      to_linearize.clear();
    }
  }

  // Extension (fold-in): the entering factors, folded in when every one of them can be; false
  // (nothing changed) otherwise.
  bool foldInNewFactors(const std::vector<int>& entering, UpdateStats* st) {
    const int cliques = fold_in.foldInAll(entering, foldInContext(), &tree);
    if (cliques < 0) return false;
    st->cliques_updated += cliques;
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
        (decay.reorderDue() || top_size > opt.batch.top_share * static_cast<double>(num_variables));
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
      decay.reorderingStarted();
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
      decay.orderedAfresh(tree, relinearizationPending());
    } else {
      maybeCheckOrderingDecay();
    }
    return !top.variables.empty();
  }

  // BatchSwitchOptions::reorder_decay (bayestree/ordering_decay.h). With async, a job
  // re-orders (the next update's snapshot), from the sooner decay of
  // AsyncRelinearizationOptions::reorder_decay; without a second core, the update re-orders.
  void maybeCheckOrderingDecay() {
    decay.check(
        tree,
        {factors, fixed, nestedDissectionMin(), nestedDissectionTryFlops(), &threads.lanes[0].slot},
        {opt.batch.reorder_decay, backgroundJobsAllowed() && opt.async.reorder_in_background,
         opt.async.reorder_decay});
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
      updated.noteAll();
      relinearization_check.scanAll();
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
    updated.begin();
    const auto out = partial_solve.run(&tree, false, opt.wildfire_threshold, entriesOf(budget_mb),
                                       &delta, &threads);
    st.cliques_solved = out.solved;
    st.cliques_deferred = out.deferred;
    noteSolved();
    updated.finish(fixed);
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
    if (num_custom == 0) {
      for (const Factor<G>& e : factors.factors)
        f += weighted ? e.inlierWeight() * e.cost(poses) : e.cost(poses);
      return f;
    }
    for (int k = 0; k < factors.numFactors(); ++k) {  // a factor of your own may fail
      const Factor<G>& e = factors.factors[k];
      try {
        f += weighted ? e.inlierWeight() * e.cost(poses) : e.cost(poses);
      } catch (...) {
        throwFactorError(factorText(e, k, poses), k);
      }
    }
    return f;
  }

  // Powell's dogleg step on the Bayes tree (bayestree/dogleg_step.h) into Δ.
  void doglegStep() {
    delta = bayestree::doglegStep<D>(tree.cliques, partial_solve.delta_newton, &dogleg_radius,
                                     opt.dogleg_min_radius, [&](const std::vector<Vec>& x) {
                                       // A point where a factor of your own fails is rejected
                                       // (the radius shrinks), as Ceres does.
                                       try {
                                         return objectiveAt(x);
                                       } catch (const std::exception&) {
                                         return std::numeric_limits<double>::infinity();
                                       }
                                     });
  }

  // Passes of Alg. 6 with every variable relinearised and the whole tree re-eliminated, until F
  // settles (Gauss–Newton steps halved while F rises).
  UpdateStats relinearizeAll(const CancellationToken* cancel) {
    const auto t0 = Clock::now();
    UpdateStats total;
    async.dropBuffers();
    if (relinearizationPending()) {  // everything is relinearised below: the job is not needed
      async.abandon();
      relinearization_check.scanAll();  // the snapshot's check consumed its candidates
    }
    if (!queued.empty() || !new_vars.empty()) accumulate(&total, update());
    updated.begin();
    updated.noteAll();  // every Δ is set (and may be halved) below
    try {
      refine(cancel, &total);
    } catch (...) {  // a factor of your own failed: the last completed iteration stands
      relinearization_check.scanAll();
      updated.finish(fixed);
      throw;
    }
    relinearization_check.scanAll();  // the halving set Δ outside the solve
    updated.finish(fixed);
    total.time_s = secondsSince(t0);
    return total;
  }

  // relinearizeAll's iterations.
  void refine(const CancellationToken* cancel, UpdateStats* total_out) {
    UpdateStats& total = *total_out;
    double F_prev = objectiveAt(delta);
    StepOptions everything;
    everything.relinearize_all = true;
    for (int it = 0; it < opt.finalize_max_iterations; ++it) {
      if (cancel != nullptr && cancel->cancelled()) {
        total.cancelled = true;
        break;
      }
      ++total.refine_iterations;
      // A failing factor of your own undoes this iteration (the estimate is the last one's).
      if (num_custom > 0) {
        beginJournal();
        try {
          accumulate(&total, step(everything));
        } catch (...) {
          rollBack();
          throw;
        }
        endJournal();
      } else {
        accumulate(&total, step(everything));
      }
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
void IncrementalSmoother<G>::discardQueuedFactor(int index) {
  impl_->discardQueuedFactor(index);
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
  impl_->async.second_core_busy = busy;
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
  return impl_->updated.inOrder();
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
