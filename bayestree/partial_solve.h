// The partial state update (IJRR 2012 Alg. 7, "wildfire"): back-substitution top-down from the
// roots, entering a clique only if it was re-eliminated (or folded into) or a separator variable
// changed by at least the threshold α since the value the clique's subtree was last solved with;
// independent subtrees on different threads.
//
// With a solve budget (Extension, docs/design.md "A bounded back-substitution"), the cliques the
// update re-eliminated or folded into are solved as always, and the others the wildfire enters
// once the entries of [L; Sᵀ] read reach the budget are deferred: each keeps the separator
// variables it has not seen move (Clique::unseen), and later updates solve the backlog, oldest
// first, with what their budget has left.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "arbor_slam/bayestree/bayes_tree.h"
#include "arbor_slam/bayestree/update_threads.h"

namespace arbor::bayestree {

/// D: the dimension of one variable.
template <int D>
class PartialSolve {
 public:
  using Vec = Eigen::Matrix<double, D, 1>;

  /// What a solve did.
  struct Output {
    int solved = 0;      ///< cliques solved
    int on_helpers = 0;  ///< of them, by helper threads
    int deferred = 0;    ///< cliques deferred after the solve (BayesTree::num_deferred)
  };

  std::vector<Vec> delta_newton;  ///< the Gauss–Newton solution of the Bayes tree, per pose
  std::vector<Vec> delta_seen;    ///< Δ_newton as last propagated to the cliques below
  /// The frontals of the cliques the last run() solved (each once; in no particular order when
  /// helper threads took part): the only variables whose Δ it can have changed.
  std::vector<int> solved_variables;

  /// A new pose (Δ = 0).
  void addVariable();
  /// A relinearised pose: its Δ is zero at the new linearisation point.
  void resetVariable(int v);

  /// Solves the cliques that need it (`full`: every clique) into delta_newton and, when `delta`
  /// is not null, into *delta too; α = `threshold`. `budget` > 0 (and not `full`): once the
  /// entries read (solveEntries, every clique solved counted) reach `budget`, a clique that is
  /// not dirty (re-eliminated or folded into) is deferred instead of solved; on one thread.
  /// 0: no budget (a backlog left by an earlier budgeted run is solved too).
  Output run(BayesTree<D>* tree, bool full, double threshold, double budget,
             std::vector<Vec>* delta, UpdateThreads* threads);

  /// What solving clique c reads: its [L; Sᵀ], d and the separator's values.
  static double solveEntries(const Clique<D>& c) {
    return static_cast<double>(c.F + c.Sn) * c.F + c.F + c.Sn;
  }

 private:
  // The budgeted walk: the roots' wildfire first, then the backlog, on the caller's lane.
  Output runBudgeted(BayesTree<D>* tree, double threshold, double budget, std::vector<Vec>* delta,
                     Lane* lane);

  // Alg. 7's test: re-eliminated or folded into (dirty), deferred with moves it has not seen
  // (unseen), or a separator variable changed by at least α in this solve.
  bool needsSolving(const Clique<D>& c) const;

  // x_f = R⁻¹ (d − S x_s) for one clique; marks the frontals that moved by at least α as
  // changed.
  void solveClique(const Clique<D>& c, bool full, double threshold, std::vector<Vec>* delta,
                   Lane* lane);

  std::vector<char> changed_;         // per pose: moved by ≥ α in this solve (restored to 0)
  std::vector<int> stack_, backlog_;  // runBudgeted's walk and the backlog it starts from
};

extern template class PartialSolve<3>;
extern template class PartialSolve<6>;

}  // namespace arbor::bayestree
