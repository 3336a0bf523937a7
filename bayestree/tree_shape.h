// The shape of the Bayes tree a symbolic elimination makes (bayestree/elimination_plan.h): its
// cliques, the flops of factorising it and the doubles its matrices hold, with and without the
// cached factors a CachedFactorOptions ratio drops (docs/design.md, "Memory"). Symbolic only:
// what the smoother's tree would hold after re-eliminating that plan, without building it.
#pragma once

#include <algorithm>
#include <utility>
#include <vector>

#include "arbor_slam/bayestree/bayes_tree.h"
#include "arbor_slam/bayestree/elimination_plan.h"

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

/// What a new factor on variables a and b costs an exact smoother in the tree of `plan`, read
/// off the cliques it reaches: the cliques holding a or b as frontals and every ancestor of
/// them (Kaess et al. 2012, Alg. 4: the top iSAM2 re-eliminates).
///   re-elimination:  Σ BayesTree::cliqueFlops over that top (its cliques re-eliminated as they
///     are; a fresh ordering of the top changes the shapes, not the order of magnitude);
///   rewritten:       the doubles of the conditionals [R S] an update of the square-root factor
///     by the factor's rows must rewrite: a row of R that the factor's rows are rotated with
///     changes in all of its entries, and they fill to every column after. Row r of a clique of
///     Fₙ frontal variables holds D(Fₙ − r) + S entries; the rows enter the cliques holding a or
///     b at that variable's row, and each parent at the row of the child's first separator
///     variable (the child's separator fills), and every row after it changes;
///   rank update:     2·D·rewritten, the flops of a Householder update of those rows by D rows
///     (PathCost::rankUpdateFlops).
struct PathCost {
  int cliques = 0;
  double reelimination_flops = 0;
  double rewritten_doubles = 0;
  template <int D>
  double rankUpdateFlops() const {
    return 2.0 * D * rewritten_doubles;
  }
};

/// PathCost of a factor on local variables a and b (a == b: a unary factor). `seen` is scratch
/// of plan.cliques.size() ints, all different from `stamp` on entry (a caller keeps one and
/// passes a new stamp each call). O(the top's cliques' frontal variables).
template <int D>
PathCost pathCost(const EliminationPlan& plan, int a, int b, std::vector<int>* seen, int stamp) {
  // The cliques reached, each with the first of its frontal rows the factor's rows reach.
  std::vector<std::pair<int, size_t>> reached;
  auto rowOf = [&](int c, int v) {
    const std::vector<int>& f = plan.cliques[static_cast<size_t>(c)].frontals;
    return static_cast<size_t>(std::find(f.begin(), f.end(), v) - f.begin());
  };
  for (const int v : {a, b}) {
    int c = plan.clique_of_variable[static_cast<size_t>(v)];
    size_t row = rowOf(c, v);
    while (c >= 0) {
      int& mark = (*seen)[static_cast<size_t>(c)];
      if (mark == stamp) {  // the rest of the path is counted already, from this row or before
        for (auto& [clique, first] : reached)
          if (clique == c) first = std::min(first, row);
        break;
      }
      mark = stamp;
      reached.emplace_back(c, row);
      const SymbolicClique& clique = plan.cliques[static_cast<size_t>(c)];
      if (clique.parent >= 0) row = rowOf(clique.parent, clique.separator.front());
      c = clique.parent;
    }
  }
  PathCost cost;
  for (const auto& [c, first] : reached) {
    const SymbolicClique& clique = plan.cliques[static_cast<size_t>(c)];
    const size_t nf = clique.frontals.size();
    const double S = static_cast<double>(clique.separator.size()) * D;
    ++cost.cliques;
    cost.reelimination_flops += BayesTree<D>::cliqueFlops(nf, clique.separator.size());
    for (size_t r = first; r < nf; ++r)
      cost.rewritten_doubles += D * (D * static_cast<double>(nf - r) + S);
  }
  return cost;
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
