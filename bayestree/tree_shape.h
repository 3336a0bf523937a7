// The shape of the Bayes tree a symbolic elimination makes (bayestree/elimination_plan.h): its
// cliques, the flops of factorising it and the doubles its matrices hold, with and without the
// cached factors a CachedFactorOptions ratio drops (docs/design.md, "Memory"). Symbolic only:
// what the smoother's tree would hold after re-eliminating that plan, without building it.
#pragma once

#include <algorithm>
#include <vector>

#include "arbor/bayestree/bayes_tree.h"
#include "arbor/bayestree/elimination_plan.h"

namespace arbor::bayestree {

struct TreeShape {
  int cliques = 0;
  double flops = 0;                ///< Σ BayesTree::cliqueFlops
  double conditional_doubles = 0;  ///< Σ F(F+S) + F: the conditionals and their d
  double cached_doubles = 0;       ///< Σ S² + S over the cliques that keep their cached factor
  double dropped_doubles = 0;      ///< Σ S² + S over those that keep none
  int cliques_without_cached = 0;
  int max_frontal_dim = 0, max_separator_dim = 0;

  /// BayesTree::doubles of such a tree, and of the one that keeps every cached factor.
  double doubles() const { return conditional_doubles + cached_doubles; }
  double allKeptDoubles() const { return doubles() + dropped_doubles; }
};

/// The shape of the cliques of `plan` over variables of dimension D, keeping the cached factors
/// BayesTree::keepsCachedFactor keeps at `cached_factor_max_ratio`. O(cliques).
template <int D>
TreeShape treeShape(const EliminationPlan& plan, double cached_factor_max_ratio) {
  TreeShape s;
  for (const SymbolicClique& c : plan.cliques) {
    const size_t nf = c.frontals.size(), ns = c.separator.size();
    const bool cached = BayesTree<D>::keepsCachedFactor(nf, ns, cached_factor_max_ratio);
    const double all = BayesTree<D>::cliqueDoubles(nf, ns, true);
    const double conditional = BayesTree<D>::cliqueDoubles(nf, ns, false);
    ++s.cliques;
    s.flops += BayesTree<D>::cliqueFlops(nf, ns);
    s.conditional_doubles += conditional;
    (cached ? s.cached_doubles : s.dropped_doubles) += all - conditional;
    s.cliques_without_cached += cached ? 0 : 1;
    s.max_frontal_dim = std::max(s.max_frontal_dim, static_cast<int>(nf) * D);
    s.max_separator_dim = std::max(s.max_separator_dim, static_cast<int>(ns) * D);
  }
  return s;
}

/// The plan of a top of n variables (`rows`, the variables of a larger `group` last, as
/// constrainedColamd): nested dissection when n ≥ nested_dissection_min; otherwise CCOLAMD and,
/// when try_flops > 0, n ≥ 100 and that plan's factorisation costs more than try_flops flops per
/// variable, nested dissection as well, the plan of fewer flops kept. (An ordering costs
/// microseconds per variable; a top that heavy costs far more to factorise.)
template <int D>
EliminationPlan planTop(int n, const RowList& rows, const std::vector<int>& group,
                        int nested_dissection_min, double try_flops) {
  if (n >= nested_dissection_min)
    return planElimination(n, rows, constrainedNestedDissection(n, rows, group));
  EliminationPlan plan = planElimination(n, rows, constrainedColamd(n, rows, group));
  if (!(try_flops > 0) || n < 100) return plan;
  const double flops = treeShape<D>(plan, 0).flops;
  if (flops <= try_flops * n) return plan;
  EliminationPlan nd = planElimination(n, rows, constrainedNestedDissection(n, rows, group));
  return treeShape<D>(nd, 0).flops < flops ? nd : plan;
}

}  // namespace arbor::bayestree
