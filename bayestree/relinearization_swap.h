// The swap of asynchronous relinearisation (docs/design.md, "Asynchronous relinearisation"): a
// tree built off the update path — a relinearisation job's (async_relinearization.h) or a
// catch-up's — becomes the smoother's, and everything the smoother did since the tree's start is
// queued for one ordinary pass to fold in. Pure functions on values: the smoother
// (incremental_smoother.cc) hands in the base and a view of itself, and installs the result.
#pragma once

#include <vector>

#include "arbor_slam/bayestree/async_relinearization.h"
#include "arbor_slam/bayestree/bayes_tree.h"
#include "arbor_slam/bayestree/linear_factors.h"
#include "arbor_slam/bayestree/partial_solve.h"
#include "arbor_slam/core/factor.h"

namespace arbor::bayestree {

/// What changed since a snapshot besides the poses and factors added since, recorded while a
/// job or a catch-up is pending: poses moved (transformPoses), factors reweighted
/// (setFactorWeight), anchors released (releaseFixedPose). Repeats allowed.
struct SinceSnapshot {
  std::vector<int> moved, reweighted, released;
  void clear() {
    moved.clear();
    reweighted.clear();
    released.clear();
  }
};

/// A tree to swap in and what it was built from: its first n poses and f factors at Θ = theta;
/// `fixed`: per pose, not a variable of the tree (held fixed, or not in it); the poses whose Θ
/// differs from the smoother's at the base's start (`relinearized`, increasing, or every pose
/// when `all_relinearized`) with the smoother's Θ then (`theta_before`, parallel, or per pose).
template <class G>
struct SwapBase {
  static constexpr int D = G::kDoF;
  int n = 0, f = 0;
  std::vector<char> fixed;
  std::vector<G> theta;
  std::vector<int> relinearized;
  bool all_relinearized = false;
  std::vector<G> theta_before;
  BayesTree<D> tree;
  LinearizedFactors<G> factors;
  PartialSolve<D> solve;
  std::vector<typename G::Tangent> delta;
};

/// A finished job's result as a base. Reads the snapshot's factors' count only (the caller
/// keeps the array for the next snapshot's copy).
template <class G>
SwapBase<G> baseOfJob(RelinearizationSnapshot<G>&& snapshot, RelinearizedTree<G>&& job);

/// What the swap reads of the smoother the base catches up with (`src`).
template <class G>
struct SwapSource {
  const std::vector<G>& theta;             ///< Θ now, every pose
  const std::vector<char>& fixed;          ///< held fixed now
  const LinearizedFactors<G>& factors;     ///< every factor added, with its weight now
  const std::vector<Factor<G>>* queued;    ///< the queue, requeued after them (null: not)
  const std::vector<int>& to_relinearize;  ///< factors the next pass was to relinearise
  const SinceSnapshot& since;              ///< what changed since the base's start
};

/// The smoother's state on the base, and what its next pass does: `touch` and `readmitted` are
/// appended to the smoother's own lists (to_touch, readmitted), the rest replaces its fields.
template <class G>
struct Rebased {
  static constexpr int D = G::kDoF;
  std::vector<G> theta;
  BayesTree<D> tree;
  LinearizedFactors<G> factors;
  PartialSolve<D> solve;
  std::vector<typename G::Tangent> delta;
  std::vector<Factor<G>> queued;    ///< the factors added since (their indices stay), then src's
  std::vector<int> to_relinearize;  ///< src's pending ones in the base, reweighted, moved
  std::vector<int> touch;           ///< variables whose cliques the next pass re-eliminates
  std::vector<int> readmitted;      ///< factors back from weight 0: enter the next pass anew
  std::vector<int> new_vars;        ///< new to the base's tree: not in it, or added since
};

/// The base with everything src has that it lacks, as one ordinary pass folds it in: the
/// factors added since (and src's queue), the poses new to the base's graph (added since, not
/// in it, or released since: their neighbours' cliques are re-eliminated), the poses moved
/// since (Θ moved alike: θ_now θ_then⁻¹ on the left; their factors relinearised) and the
/// factors reweighted since (in or out of the structure as setFactorWeight takes them). Each
/// factor is then linearised at the base's Θ, as relinearising at the snapshot and then
/// applying the later updates inline would have it. Reads src only.
template <class G>
Rebased<G> rebase(SwapBase<G>&& base, const SwapSource<G>& src);

/// A catch-up's rebased state: the poses among r->new_vars with no factor in it (attached, or
/// of weight > 0, or queued with weight > 0) are not variables there yet — their edges wait in
/// the update's queue the catch-up leaves out. Removes them from r->new_vars and returns them,
/// for the catch-up to hold fixed (they are new to the tree at the swap).
template <class G>
std::vector<int> holdUnattached(Rebased<G>* r);

extern template SwapBase<SE2> baseOfJob(RelinearizationSnapshot<SE2>&&, RelinearizedTree<SE2>&&);
extern template SwapBase<SE3> baseOfJob(RelinearizationSnapshot<SE3>&&, RelinearizedTree<SE3>&&);
extern template Rebased<SE2> rebase(SwapBase<SE2>&&, const SwapSource<SE2>&);
extern template Rebased<SE3> rebase(SwapBase<SE3>&&, const SwapSource<SE3>&);
extern template std::vector<int> holdUnattached(Rebased<SE2>*);
extern template std::vector<int> holdUnattached(Rebased<SE3>*);

}  // namespace arbor::bayestree
