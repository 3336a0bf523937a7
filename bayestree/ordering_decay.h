// The re-ordering decay watch (BatchSwitchOptions::reorder_decay, docs/design.md "Never costlier
// than batch"): an incremental ordering decays as fill-in accumulates, so once the tree's flops
// or its doubles have grown by the decay factor since the last comparison, both are compared
// with those of the whole graph in a fresh ordering. Past decay × fresh, the next
// re-elimination re-orders the whole graph (reorderDue), or, with a sooner background decay, a
// relinearisation job re-orders it off the update path (jobWanted).
//
// Invariants: the references are the tree's flops and doubles at its last fresh ordering or
// comparison; reorderDue() and jobWanted() are set only by check() and cleared only by the
// smoother's reorderingStarted / orderedAfresh / adoptedFresh. The check reads the tree and the
// factors and writes nothing but the watch (and the caller's per-pose slot, restored to −1).
#pragma once

#include <algorithm>
#include <vector>

#include "arbor_slam/bayestree/bayes_tree.h"
#include "arbor_slam/bayestree/elimination_plan.h"
#include "arbor_slam/bayestree/linear_factors.h"

namespace arbor::bayestree {

/// When the watch compares and re-orders.
struct DecayRule {
  double inline_decay = 0;      ///< BatchSwitchOptions::reorder_decay (0: the watch is off)
  bool in_background = false;   ///< a job may re-order (async, second core free, option on)
  double background_decay = 0;  ///< AsyncRelinearizationOptions::reorder_decay
};

/// The graph a fresh ordering is planned for: the factors in the structure between poses not
/// held fixed and in the tree, ordered as the top elimination would order a top of all of them.
template <class G>
struct DecayGraph {
  const LinearizedFactors<G>& factors;
  const std::vector<char>& fixed;
  int nested_dissection_min = 0;           ///< SmootherOptions, resolved for G
  double nested_dissection_try_flops = 0;  ///< SmootherOptions, resolved for G (planTop)
  std::vector<int>* slot;                  ///< per pose, −1 (scratch; restored)
};

template <class G>
class OrderingDecay {
 public:
  static constexpr int D = G::kDoF;

  /// A decay past the inline factor was found: the next re-elimination re-orders the graph.
  bool reorderDue() const { return reorder_due_; }
  /// A decay past the background factor was found: the next snapshot's job re-orders.
  bool jobWanted() const { return job_wanted_; }

  /// The whole graph is about to be re-eliminated in a fresh ordering.
  void reorderingStarted() { reorder_due_ = false; }
  /// The tree was just ordered afresh: the watch measures from it. A wanted job stays wanted
  /// while one is in flight (its tree, swapped in, settles it).
  void orderedAfresh(const BayesTree<D>& tree, bool job_in_flight) {
    flops_reference_ = tree.flops;
    doubles_reference_ = tree.doubles;
    if (!job_in_flight) job_wanted_ = false;
  }
  /// A job's tree, ordered afresh, came in: nothing is due or wanted.
  void adoptedFresh(const BayesTree<D>& tree) {
    flops_reference_ = tree.flops;
    doubles_reference_ = tree.doubles;
    reorder_due_ = false;
    job_wanted_ = false;
  }

  /// After an incremental change of the tree: once its flops or doubles passed decay × their
  /// references (decay: the inline one, or the sooner background one when a job may
  /// re-order), compares both with a fresh ordering's and sets jobWanted (past the background
  /// decay, none wanted yet) or reorderDue (past the inline decay); the references become the
  /// tree's. Below 10⁶ flops and 10⁶ doubles a re-ordering saves less than the check costs.
  void check(const BayesTree<D>& tree, const DecayGraph<G>& graph, const DecayRule& rule) {
    if (rule.inline_decay <= 0) return;
    const double decay =
        rule.in_background ? std::min(rule.inline_decay, rule.background_decay) : rule.inline_decay;
    if (tree.flops <= decay * std::max(flops_reference_, kMinCheckFlops) &&
        tree.doubles <= decay * std::max(doubles_reference_, kMinCheckDoubles))
      return;
    compare(tree, graph, rule, decay);
  }

  /// Flops of factorising every variable in the tree in a fresh ordering, and in *doubles the
  /// doubles its cliques would hold. O(n + m).
  double freshOrderingCost(const BayesTree<D>& tree, const DecayGraph<G>& graph, double* doubles);

 private:
  double flops_reference_ = 0, doubles_reference_ = 0;
  static constexpr double kMinCheckFlops = 1e6;
  static constexpr double kMinCheckDoubles = 1e6;  // 8 MB
  // check() past the references: the comparison with a fresh ordering.
  void compare(const BayesTree<D>& tree, const DecayGraph<G>& graph, const DecayRule& rule,
               double decay);

  bool reorder_due_ = false;
  bool job_wanted_ = false;
  RowList fresh_rows_;  // scratch of freshOrderingCost
  std::vector<int> fresh_vars_;
};

extern template class OrderingDecay<SE2>;
extern template class OrderingDecay<SE3>;

}  // namespace arbor::bayestree
