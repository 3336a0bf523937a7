#include "arbor_slam/bayestree/ordering_decay.h"

#include <algorithm>

#include "arbor_slam/bayestree/tree_shape.h"

namespace arbor::bayestree {

template <class G>
void OrderingDecay<G>::compare(const BayesTree<D>& tree, const DecayGraph<G>& graph,
                               const DecayRule& rule, double decay) {
  // A decay past the inline factor while a job is wanted already (found again before its tree
  // is swapped in) re-orders inline.
  double fresh_doubles = 0;
  const double fresh_flops = freshOrderingCost(tree, graph, &fresh_doubles);
  const auto past = [&](double d) {
    return tree.flops > d * fresh_flops || tree.doubles > d * fresh_doubles;
  };
  if (rule.in_background && !job_wanted_ && past(decay))
    job_wanted_ = true;
  else if (past(rule.inline_decay))
    reorder_due_ = true;
  flops_reference_ = tree.flops;
  doubles_reference_ = tree.doubles;
}

template <class G>
double OrderingDecay<G>::freshOrderingCost(const BayesTree<D>& tree, const DecayGraph<G>& graph,
                                           double* doubles) {
  std::vector<int>& slot = *graph.slot;
  std::vector<int>& vars = fresh_vars_;
  vars.clear();
  const int num_poses = static_cast<int>(graph.fixed.size());
  for (int v = 0; v < num_poses; ++v)
    if (!graph.fixed[v] && tree.clique_of[v] >= 0) {
      slot[v] = static_cast<int>(vars.size());
      vars.push_back(v);
    }
  const int n = static_cast<int>(vars.size());
  fresh_rows_.clear();
  const LinearizedFactors<G>& factors = graph.factors;
  for (int f = 0; f < factors.numFactors(); ++f) {
    if (!factors.attached[f]) continue;  // weight 0: not in the structure
    const Factor<G>& e = factors.factors[f];
    int keys = 0;
    for (int k = 0; k < e.arity(); ++k) keys += slot[e.key(k)] >= 0 ? 1 : 0;
    if (keys < 2) continue;
    for (int k = 0; k < e.arity(); ++k)
      if (slot[e.key(k)] >= 0) fresh_rows_.add(slot[e.key(k)]);
    fresh_rows_.endRow();
  }
  for (int v : vars) slot[v] = -1;
  const std::vector<int> group(static_cast<size_t>(n), 0);
  const EliminationPlan plan = planTop<D>(n, fresh_rows_, group, graph.nested_dissection_min,
                                          graph.nested_dissection_try_flops);
  const TreeShape shape = treeShape<D>(plan, tree.cached_factors.max_ratio);
  *doubles =
      tree.dropsCachedFactors(shape.allKeptDoubles()) ? shape.doubles() : shape.allKeptDoubles();
  return shape.flops;
}

template class OrderingDecay<SE2>;
template class OrderingDecay<SE3>;

}  // namespace arbor::bayestree
