// The partial state update (IJRR 2012 Alg. 7, "wildfire"): back-substitution top-down from the
// roots, entering a clique only if it was re-eliminated (or folded into) or a separator variable
// changed by at least the threshold α since the value the clique's subtree was last solved with;
// independent subtrees on different threads.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "arbor/bayestree/bayes_tree.h"
#include "arbor/bayestree/update_threads.h"

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
  /// is not null, into *delta too; α = `threshold`.
  Output run(BayesTree<D>* tree, bool full, double threshold, std::vector<Vec>* delta,
             UpdateThreads* threads);

 private:
  // x_f = R⁻¹ (d − S x_s) for one clique; marks the frontals that moved by at least α as
  // changed.
  void solveClique(const Clique<D>& c, bool full, double threshold, std::vector<Vec>* delta,
                   Lane* lane);

  std::vector<char> changed_;  // per pose: moved by ≥ α in this solve (restored to 0)
};

extern template class PartialSolve<3>;
extern template class PartialSolve<6>;

}  // namespace arbor::bayestree
