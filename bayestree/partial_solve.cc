#include "arbor_slam/bayestree/partial_solve.h"

#include <deque>
#include <limits>

#include "arbor_slam/bayestree/dense_kernels.h"

namespace arbor::bayestree {
namespace {

// A back-substitution subtree that reads fewer entries of [L; Sᵀ] than this stays on one thread
// (a helper's wake-up and the hand-over would cost more than they save; tuned on intel and
// parking-garage).
constexpr double kMinSharedSolve = 20000;

}  // namespace

template <int D>
void PartialSolve<D>::addVariable() {
  delta_newton.push_back(Vec::Zero());
  delta_seen.push_back(Vec::Zero());
  changed_.push_back(0);
}

template <int D>
void PartialSolve<D>::resetVariable(int v) {
  delta_newton[v].setZero();
  delta_seen[v].setZero();
}

template <int D>
bool PartialSolve<D>::needsSolving(const Clique<D>& c) const {
  if (c.dirty || !c.unseen.empty()) return true;
  for (int v : c.separator)
    if (changed_[v]) return true;
  return false;
}

template <int D>
typename PartialSolve<D>::Output PartialSolve<D>::run(BayesTree<D>* tree, bool full,
                                                      double threshold, double budget,
                                                      std::vector<Vec>* delta,
                                                      UpdateThreads* threads) {
  if (!full && (budget > 0 || tree->num_deferred > 0)) {
    for (Lane& l : threads->lanes) {
      l.solved = 0;
      l.solved_list.clear();
    }
    return runBudgeted(tree, threshold,
                       budget > 0 ? budget : std::numeric_limits<double>::infinity(), delta,
                       &threads->lanes[0]);
  }
  if (full) tree->clearAllUnseen();  // every clique is solved below
  const std::vector<Clique<D>>& cliques = tree->cliques;
  auto needs_solving = [&](const Clique<D>& c) { return full || needsSolving(c); };
  for (Lane& l : threads->lanes) {
    l.solved = 0;
    l.solved_list.clear();
  }
  // Depth-first from the roots on this thread, until a subtree worth sharing waits (the oldest
  // entry of the stack is the largest subtree waiting): small walks never involve a helper.
  auto worth_sharing = [&](const std::deque<int>& pending) {
    return pending.size() > 1 && cliques[pending.front()].subtree_entries >= kMinSharedSolve;
  };
  // Solves the top of `lane`'s stack and stacks the children that need solving (a child's
  // separator lies in this clique's frontals ∪ separator, all solved by now): Alg. 7 step 2,
  // "For all variables Δ_kj in Δ_k that change by more than threshold α: recursively process
  // each descendant containing such a variable".
  auto solve_next = [&](int lane) {
    std::deque<int>& stack = threads->lanes[lane].pending;
    const int c = stack.back();
    stack.pop_back();
    solveClique(tree->cliques[c], full, threshold, delta, &threads->lanes[lane]);
    tree->cliques[c].dirty = false;
    for (int ch : cliques[c].children)
      if (needs_solving(cliques[ch])) stack.push_back(ch);
  };
  const bool can_share = threads->lanes.size() > 1;
  std::deque<int>& pending = threads->lanes[0].pending;
  pending.clear();
  for (int r : tree->roots)
    if (needs_solving(cliques[r])) pending.push_back(r);
  while (!pending.empty() && !(can_share && worth_sharing(pending))) solve_next(0);
  // Then with the helpers: each thread walks a subtree depth-first on a stack of its own and
  // hands the oldest entry to a thread that has run out of work.
  if (!pending.empty()) {
    std::vector<int>& ready = threads->ready;
    ready.assign(pending.begin(), pending.end());
    threads->workers.run(ready, [&](int lane, int id) {
      std::deque<int>& stack = threads->lanes[lane].pending;
      stack.assign(1, id);
      while (!stack.empty()) {
        solve_next(lane);
        if (worth_sharing(stack) && threads->workers.hungry()) {
          threads->workers.push(stack.front());
          stack.pop_front();
        }
      }
      return -1;
    });
  }
  Output out;
  solved_variables.clear();
  for (size_t l = 0; l < threads->lanes.size(); ++l) {
    Lane& lane = threads->lanes[l];
    if (l == 0)
      solved_variables.swap(lane.solved_list);  // the usual case: one lane solved them all
    else
      solved_variables.insert(solved_variables.end(), lane.solved_list.begin(),
                              lane.solved_list.end());
    out.solved += lane.solved;
    if (l > 0) out.on_helpers += lane.solved;
    for (int v : lane.changed_list) changed_[v] = 0;
    lane.changed_list.clear();
  }
  out.deferred = tree->num_deferred;
  return out;
}

template <int D>
typename PartialSolve<D>::Output PartialSolve<D>::runBudgeted(BayesTree<D>* tree, double threshold,
                                                              double budget,
                                                              std::vector<Vec>* delta, Lane* lane) {
  std::vector<Clique<D>>& cliques = tree->cliques;
  double spent = 0;
  // Depth-first from the cliques on stack_ (Alg. 7 step 2), a clique that was not re-eliminated
  // or folded into deferred once the budget is spent: it records the separator variables that
  // moved (changed_) as unseen, and its subtree waits with it.
  auto walk = [&]() {
    while (!stack_.empty()) {
      const int id = stack_.back();
      stack_.pop_back();
      Clique<D>& c = cliques[id];
      if (!c.in_use || !needsSolving(c)) continue;  // a backlog entry solved since
      if (!c.dirty && spent >= budget) {
        for (int v : c.separator)
          if (changed_[v]) tree->addUnseen(id, v);
        continue;
      }
      // The moves it had not seen are changes for the cliques below that hold them.
      for (int v : c.unseen)
        if (!changed_[v]) {
          changed_[v] = 1;
          lane->changed_list.push_back(v);
        }
      tree->clearUnseen(id);
      solveClique(c, /*full=*/false, threshold, delta, lane);
      spent += solveEntries(c);
      c.dirty = false;
      for (int ch : c.children)
        if (needsSolving(cliques[ch])) stack_.push_back(ch);
    }
  };
  stack_.clear();
  for (auto r = tree->roots.rbegin(); r != tree->roots.rend(); ++r)
    if (needsSolving(cliques[*r])) stack_.push_back(*r);
  walk();
  // The backlog, oldest first, while the budget lasts; cliques deferred by this run were
  // appended to tree->deferred and stay behind it.
  backlog_.swap(tree->deferred);
  tree->deferred.clear();
  size_t k = 0;
  for (; k < backlog_.size() && spent < budget; ++k) {
    stack_.push_back(backlog_[k]);
    walk();
  }
  std::vector<int> newly = std::move(tree->deferred);
  tree->deferred.clear();
  for (; k < backlog_.size(); ++k) {
    const int id = backlog_[k];
    if (cliques[id].in_use && !cliques[id].unseen.empty()) tree->deferred.push_back(id);
  }
  for (int id : newly)
    if (cliques[id].in_use && !cliques[id].unseen.empty()) tree->deferred.push_back(id);
  backlog_.clear();
  Output out;
  out.solved = lane->solved;
  out.deferred = tree->num_deferred;
  solved_variables.assign(lane->solved_list.begin(), lane->solved_list.end());
  for (int v : lane->changed_list) changed_[v] = 0;
  lane->changed_list.clear();
  return out;
}

// Alg. 7 step 1, "For current clique C_k = F_k : S_k compute update Δ_k of frontal variables F_k
// from the local conditional density P(F_k | S_k)".
template <int D>
void PartialSolve<D>::solveClique(const Clique<D>& c, bool full, double threshold,
                                  std::vector<Vec>* delta, Lane* lane) {
  ++lane->solved;
  const int nf = static_cast<int>(c.frontals.size());
  const int ns = static_cast<int>(c.separator.size());
  const int F = c.F;
  // z = [x_f; x_s]: the separator's values in, the frontals' out (bayestree/dense_kernels.h).
  const int N = F + c.Sn;
  lane->x.resize(N);
  double* x = lane->x.data();
  for (int b = 0; b < ns; ++b) Eigen::Map<Vec>(x + F + b * D) = delta_newton[c.separator[b]];
  solveConditional(c.lsPtr(), c.ld, N, F, c.dPtr(), x);
  // The new values are always taken. A variable is "changed" (the cliques below that hold it
  // in their separator must be recomputed) when it moved by at least the threshold from the
  // value they were last solved with (delta_seen), so small moves cannot accumulate.
  for (int a = 0; a < nf; ++a) {
    const int v = c.frontals[a];
    const Eigen::Map<const Vec> xv(x + a * D);
    if (full || (xv - delta_seen[v]).cwiseAbs().maxCoeff() >= threshold) {
      delta_seen[v] = xv;
      if (!changed_[v]) {
        changed_[v] = 1;
        lane->changed_list.push_back(v);
      }
    }
    delta_newton[v] = xv;
    if (delta) (*delta)[v] = xv;
    lane->solved_list.push_back(v);
  }
}

template class PartialSolve<3>;
template class PartialSolve<6>;

}  // namespace arbor::bayestree
