// Re-eliminating the removed top of the Bayes tree (IJRR 2012 Alg. 4 steps 3–6): the structure
// of its factors and of the orphans' cached factors, a constrained ordering (CCOLAMD, or nested
// dissection for large tops; bayestree/elimination_plan.h), the symbolic plan into cliques, the
// assembly of each clique's dense Hessian, its Cholesky elimination (damped when nearly
// singular), the orphans hung back below, and the walk that eliminates independent subtrees on
// different threads.
#pragma once

#include <vector>

#include "arbor_slam/bayestree/bayes_tree.h"
#include "arbor_slam/bayestree/dense_kernels.h"
#include "arbor_slam/bayestree/elimination_plan.h"
#include "arbor_slam/bayestree/linear_factors.h"
#include "arbor_slam/bayestree/update_threads.h"

namespace arbor::bayestree {

template <class G>
class TopElimination {
 public:
  static constexpr int D = G::kDoF;

  /// What the step reads.
  struct Input {
    const std::vector<int>& top;           ///< the top's variables (BayesTree::Top::variables)
    const std::vector<int>& orphans;       ///< subtrees to hang back below it
    const std::vector<char>* last_group;   ///< per pose: 1 to order last (null: unconstrained)
    const std::vector<int>& to_linearize;  ///< factors whose linearisation is left to this step
    const std::vector<G>& theta;           ///< the linearisation point (for to_linearize)
    const std::vector<char>& fixed;        ///< per pose: a gauge pose (a constant)
    int nested_dissection_min;  ///< tops of at least this many variables: nested dissection
    /// > 0: a smaller top whose CCOLAMD plan costs more than this many flops per variable is
    /// also ordered by nested dissection, the cheaper plan kept (planTop, tree_shape.h)
    double nested_dissection_try_flops = 0;
  };
  /// What it did.
  struct Output {
    int cliques = 0;        ///< new cliques
    int variables = 0;      ///< their frontal variables
    int indeterminate = 0;  ///< of them, damped
    int on_helpers = 0;     ///< of them, eliminated by helper threads
    double flops = 0;       ///< Σ BayesTree::cliqueFlops of the new cliques
  };

  /// Orders and eliminates the top into new cliques of `tree` and re-attaches the orphans;
  /// linearises `to_linearize` side by side with the ordering (all of it when the top is
  /// empty).
  Output run(const Input& in, BayesTree<D>* tree, LinearizedFactors<G>* factors,
             UpdateThreads* threads);

  /// Dense Cholesky elimination of clique `id` (its children eliminated): L = chol(H_ff),
  /// R = Lᵀ, S = R⁻ᵀH_fs, d = R⁻ᵀg_f, cached factor (H_ss − SᵀS, g_s − Sᵀd), with the scratch
  /// of `lane`. Returns true when the frontal block was nearly singular and had to be damped
  /// (Levenberg-style).
  static bool eliminateClique(int id, int lane, const std::vector<char>& fixed, BayesTree<D>* tree,
                              const LinearizedFactors<G>& factors, UpdateThreads* threads);

  /// The clique's Hessian [H g; gᵀ ·] over frontals ∪ separator, lower triangle, into the
  /// lane's h ((N+1)×(N+1), column-major; g in row N): its factors (assembledAt) and its
  /// children's cached factors.
  static void assemble(const Clique<D>& c, int lane, const std::vector<char>& fixed,
                       BayesTree<D>* tree, const LinearizedFactors<G>& factors,
                       UpdateThreads* threads);

  size_t scratchBytes() const;

 private:
  /// Once clique c is eliminated, its children without a cached factor (Clique::cached) free
  /// the one their elimination computed for c's assembly.
  static void dropChildrenCachedFactors(const Clique<D>& c, BayesTree<D>* tree);

  RowList rows_;
  std::vector<int> group_, ids_, by_need_, by_capacity_;
  std::vector<double> chain_flops_;
  std::vector<DoubleBuffer> buffers_;

  double offCriticalPathFlops(const EliminationPlan& plan);
};

extern template class TopElimination<SE2>;
extern template class TopElimination<SE3>;

}  // namespace arbor::bayestree
