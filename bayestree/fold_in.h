// Our extension, not the paper's (docs/design.md, "Loop closures by rank updates"): a factor
// whose ends are frontal in cliques on one path to the root changes the Bayes tree's matrices
// only by a rank-D term, so it is folded in by rank-D Cholesky updates of the cliques on that
// path (bayestree/clique.h) instead of re-eliminating the path (iSAM's incremental
// factorisation, Kaess, Ranganathan, Dellaert, T-RO 2008, applied clique by clique). Nothing is
// re-ordered or re-eliminated: O(D·N·F) per clique on the path instead of O(F·N²). Also: the
// flop estimates that choose between folding and re-eliminating, and the split of an update
// into the factors that introduce new poses and those folded in after.
#pragma once

#include <vector>

#include "arbor_slam/bayestree/bayes_tree.h"
#include "arbor_slam/bayestree/dense_kernels.h"
#include "arbor_slam/bayestree/linear_factors.h"
#include "arbor_slam/core/factor.h"

namespace arbor::bayestree {

template <class G>
class FoldIn {
 public:
  static constexpr int D = G::kDoF;

  /// What the fold-in reads besides the tree: the factors, the linearisation point, the fixed
  /// poses, and a per-pose slot scratch (all −1, restored on return).
  struct Context {
    const LinearizedFactors<G>& factors;
    const std::vector<G>& theta;
    const std::vector<char>& fixed;
    std::vector<int>& slot;
  };

  /// The clique of the first eliminated non-fixed end of factor f (−1 when it cannot be folded
  /// in: an end not yet in the tree, ends in different branches, or a damped clique on the way
  /// to the root). Folding one factor in leaves this unchanged for the others.
  int startClique(int f, const Context& ctx, const BayesTree<D>& tree) const;

  /// Folds factors `fs` (in that order) into the tree when every one of them can be (within
  /// its separators' budget: checked for all before the first is folded in). Returns the
  /// cliques updated, or −1 (nothing changed) when one cannot be.
  int foldInAll(const std::vector<int>& fs, const Context& ctx, BayesTree<D>* tree);
  /// foldInAll of factors first..factors.numFactors()−1.
  int foldInAll(int first, const Context& ctx, BayesTree<D>* tree);

  /// Folds factor f in (startClique(f) ≥ 0); returns the cliques updated.
  int foldIn(int f, const Context& ctx, BayesTree<D>* tree);

  /// Whether folding `factors` in (after their new poses join the tree at the root) is
  /// estimated cheaper than re-eliminating the paths from their old ends' cliques to the root.
  bool worthFolding(const std::vector<Factor<G>>& factors, const std::vector<char>& fixed,
                    BayesTree<D>* tree);

  /// Splits `queued`: keeps in it the factors that join each new pose to the tree (one per
  /// pose, or those that cannot be told apart) and returns the others, whose ends will all be
  /// in the tree. `slot`: per-pose scratch, all −1 (restored).
  static std::vector<Factor<G>> splitOffIntroducing(std::vector<Factor<G>>* queued,
                                                    const std::vector<char>& fixed,
                                                    const BayesTree<D>& tree,
                                                    std::vector<int>* slot);

  size_t scratchBytes() const;

 private:
  // Folding factor f in from clique `start`: its later end joins the separators on the way up
  // to its own clique (running intersection) until one already holds it. Sets *later to that
  // end and fills `path` with the cliques whose separator it joins (empty when none).
  void separatorsToExtend(int f, int start, const Context& ctx, const BayesTree<D>& tree,
                          int* later, std::vector<int>* path) const;
  bool withinBudget(int f, int start, const Context& ctx, const BayesTree<D>& tree);
  double foldFlops(int start, const BayesTree<D>& tree) const;
  double eliminationFlops(const std::vector<int>& starts, BayesTree<D>* tree);
  // foldIn with f's linearisation at ctx.theta given (null: linearised here).
  int foldIn(int f, const typename Factor<G>::Linearization* linearized, const Context& ctx,
             BayesTree<D>* tree);

  DoubleBuffer extend_buf_;
  DoubleBuffer w_buf_, w_parent_buf_;  // W of this clique and of its parent
  std::vector<int> path_;              // cliques whose separator a fold-in extends
  std::vector<typename Factor<G>::Linearization> linearized_;  // foldInAll's factors
  int path_stamp_ = 0;
};

extern template class FoldIn<SE2>;
extern template class FoldIn<SE3>;

}  // namespace arbor::bayestree
