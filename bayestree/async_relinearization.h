// Asynchronous relinearisation (docs/design.md, "Asynchronous relinearisation"; our extension of
// Kaess et al., "iSAM2: Incremental smoothing and mapping using the Bayes tree", IJRR 2012): the
// snapshot the owner thread takes at a relinearisation check (the factors, Θ with Θ_M ⊕ Δ_M, the
// poses held fixed), the background job that linearises every factor at that Θ and eliminates the
// whole graph in a fresh ordering into a new Bayes tree (Alg. 4 with J = every variable, as
// relinearizeAll does, then Alg. 7 over every clique), and the handle that owns at most one such
// job. The smoother (incremental_smoother.cc) takes the snapshot and swaps the result in.
#pragma once

#include <atomic>
#include <exception>
#include <memory>
#include <thread>
#include <vector>

#include "arbor_slam/bayestree/bayes_tree.h"
#include "arbor_slam/bayestree/linear_factors.h"
#include "arbor_slam/bayestree/partial_solve.h"
#include "arbor_slam/core/factor.h"

namespace arbor::bayestree {

/// What a relinearisation job reads: a copy, so the owner goes on meanwhile.
template <class G>
struct RelinearizationSnapshot {
  std::vector<G> theta;            ///< Θ with Θ_M := Θ_M ⊕ Δ_M (every pose known then)
  std::vector<char> fixed;         ///< held fixed: the gauge poses and those not in the tree yet
  std::vector<Factor<G>> factors;  ///< the factors in the tree, with their inlier weights
  std::vector<int> relinearized;   ///< M, increasing
  std::vector<G> theta_before;     ///< Θ_M before ⊕ Δ_M, parallel to `relinearized`
  int update = 0;                  ///< the update that took it (the smoother's count)
  int nested_dissection_min = 0;   ///< SmootherOptions, resolved for G
  double nested_dissection_try_flops = 0;  ///< SmootherOptions, resolved for G (planTop)
  CachedFactorOptions cached_factors;      ///< SmootherOptions::cached_factors
  /// AsyncRelinearizationOptions::job_iterations: at most this many eliminations, each after a
  /// Gauss–Newton step from the one before; fewer once F's relative decrease is below
  /// `relative_tolerance` or a halved step no longer lowers it.
  int iterations = 1;
  double relative_tolerance = 1e-6;
};

/// What it gives: the whole graph's Bayes tree at the snapshot's Θ, its linearisations and the
/// Gauss–Newton step on it.
template <class G>
struct RelinearizedTree {
  static constexpr int D = G::kDoF;
  BayesTree<D> tree;
  LinearizedFactors<G> factors;
  PartialSolve<D> solve;
  std::vector<typename G::Tangent> delta;
  int cliques = 0, indeterminate = 0;
  double cpu_seconds = 0;  ///< of the thread that ran it
  /// The eliminations run (snapshot.iterations at most). From the second on, the tree,
  /// linearisations and Δ are at `theta` (every pose stepped), not at the snapshot's Θ.
  int iterations = 1;
  std::vector<G> theta;  ///< the linearisation point when iterations > 1 (else empty)
};

/// Linearises every factor of `s` at s.theta, orders all its non-fixed poses afresh (CCOLAMD, or
/// nested dissection from s.nested_dissection_min), eliminates them into a new tree and solves
/// every clique. With s.iterations k > 1, then up to k − 1 times: Θ ← Θ ⊕ Δ (Δ halved while F =
/// Σ w eᵀΩe does not fall, at most five times; relinearizeAll allows ten and then a zero step),
/// and the same on the new Θ; it stops early when F's relative decrease falls below
/// s.relative_tolerance or no halved step lowers F. One thread; reads nothing but `s`.
template <class G>
RelinearizedTree<G> relinearizeSnapshot(const RelinearizationSnapshot<G>& s);

/// At most one relinearisation job: started from a snapshot on a background thread (at nice
/// +10, as the batch refinement: the update path comes first) or on the calling thread, taken
/// when done. The destructor waits for a running job (it reads only its own copy), so a
/// smoother destroyed mid-job neither crashes nor leaks. A copy of a handle with a job waits
/// for it and copies its result.
template <class G>
class AsyncRelinearization {
 public:
  AsyncRelinearization() = default;
  ~AsyncRelinearization();
  AsyncRelinearization(const AsyncRelinearization& other);
  AsyncRelinearization& operator=(const AsyncRelinearization& other);
  AsyncRelinearization(AsyncRelinearization&&) noexcept = default;
  AsyncRelinearization& operator=(AsyncRelinearization&& other) noexcept;

  /// Starts a job (none may be pending); `synchronous`: runs it before returning.
  /// `free_first`: the tree, linearisations and Δ a swap replaced, which the job's thread frees
  /// before its own work. Freeing them costs about a factorisation of the graph (24 ms at the
  /// median at 200,000 poses), so not on the update path; and not on a thread of its own, which
  /// would run beside the job and make glibc give one of them a heap arena of its own: the job's
  /// allocations then cannot reuse what the free returned (60% more peak RSS, measured).
  void start(RelinearizationSnapshot<G> snapshot, bool synchronous,
             RelinearizedTree<G> free_first = {});
  bool pending() const { return job_ != nullptr; }         ///< started, not yet taken
  bool done() const { return job_ && job_->done.load(); }  ///< pending and finished
  const RelinearizationSnapshot<G>& snapshot() const { return job_->snapshot; }
  /// Waits for the job and hands over its snapshot and result (rethrows what it threw).
  void take(RelinearizationSnapshot<G>* snapshot, RelinearizedTree<G>* result);
  /// Waits for a pending job and drops it.
  void abandon();

 private:
  struct Job {
    RelinearizationSnapshot<G> snapshot;
    RelinearizedTree<G> free_first;
    RelinearizedTree<G> result;
    std::exception_ptr error;
    std::atomic<bool> done{false};
    std::thread thread;
    void run();
  };
  void join() const;
  std::unique_ptr<Job> job_;
};

extern template struct RelinearizedTree<SE2>;
extern template struct RelinearizedTree<SE3>;
extern template class AsyncRelinearization<SE2>;
extern template class AsyncRelinearization<SE3>;

}  // namespace arbor::bayestree
