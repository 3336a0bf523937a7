#include "arbor_slam/bayestree/fold_in.h"

#include <algorithm>

#include <Eigen/Core>

#include "arbor_slam/core/factor_error.h"

namespace arbor::bayestree {
namespace {

// Rough flop counts that decide between folding factors in and re-eliminating their paths: a
// rank-D update of a clique costs about 4·D·F·N (plus D·Sn² for its cached factor), a
// re-elimination F³/3 + F²·Sn + F·Sn²; each also has a fixed cost per clique (assembly,
// ordering, new storage: kCliqueOverhead to re-eliminate, a quarter of it to update).
constexpr double kCliqueOverhead = 4000;

}  // namespace

template <class G>
int FoldIn<G>::startClique(int f, const Context& ctx, const BayesTree<D>& tree) const {
  const Factor<G>& e = ctx.factors.factors[f];
  int lower = -1, upper = -1;
  for (int k = 0; k < e.arity(); ++k) {
    const int v = e.key(k);
    if (ctx.fixed[v]) continue;
    if (tree.clique_of[v] < 0) return -1;
    (lower < 0 ? lower : upper) = v;
  }
  if (lower < 0) return -1;
  int start = tree.clique_of[lower];
  if (upper >= 0 && !tree.isAncestorOrSelf(tree.clique_of[upper], start)) {
    if (!tree.isAncestorOrSelf(start, tree.clique_of[upper])) return -1;
    start = tree.clique_of[upper];
  }
  for (int c = start; c >= 0; c = tree.cliques[c].parent)
    if (tree.cliques[c].damped) return -1;
  return start;
}

template <class G>
void FoldIn<G>::separatorsToExtend(int f, int start, const Context& ctx, const BayesTree<D>& tree,
                                   int* later, std::vector<int>* path) const {
  const Factor<G>& e = ctx.factors.factors[f];
  path->clear();
  *later = -1;
  if (e.arity() < 2) return;  // a unary factor lies in its clique already
  *later = tree.clique_of[e.key(0)] == start && !ctx.fixed[e.key(0)] ? e.key(1) : e.key(0);
  if (ctx.fixed[*later]) return;
  for (int c = start; c != tree.clique_of[*later]; c = tree.cliques[c].parent) {
    const auto& sep = tree.cliques[c].separator;
    if (std::find(sep.begin(), sep.end(), *later) != sep.end()) break;
    path->push_back(c);
  }
}

// Whether folding factor f in from clique `start` keeps every separator on the way within its
// budget (the fill of separatorsToExtend, which only a re-elimination, with a fresh ordering,
// keeps down).
template <class G>
bool FoldIn<G>::withinBudget(int f, int start, const Context& ctx, const BayesTree<D>& tree) {
  int later;
  separatorsToExtend(f, start, ctx, tree, &later, &path_);
  for (int c : path_)
    if (tree.cliques[c].Sn + D > tree.cliques[c].separatorBudget()) return false;
  return true;
}

template <class G>
double FoldIn<G>::foldFlops(int start, const BayesTree<D>& tree) const {
  double flops = 0;
  for (int c = start; c >= 0; c = tree.cliques[c].parent) {
    const double F = tree.cliques[c].F, S = tree.cliques[c].Sn;
    flops += 4.0 * D * F * (F + S) + D * S * S + kCliqueOverhead / 4;
  }
  return flops;
}

// The union of the paths from `starts` to the root, each clique counted once.
template <class G>
double FoldIn<G>::eliminationFlops(const std::vector<int>& starts, BayesTree<D>* tree) {
  ++path_stamp_;
  double flops = 0;
  auto& cliques = tree->cliques;
  for (int start : starts)
    for (int c = start; c >= 0 && cliques[c].path_stamp != path_stamp_; c = cliques[c].parent) {
      cliques[c].path_stamp = path_stamp_;
      const double F = cliques[c].F, S = cliques[c].Sn;
      flops += F * F * F / 3 + F * F * S + F * S * S + kCliqueOverhead;
    }
  return flops;
}

template <class G>
int FoldIn<G>::foldInAll(const std::vector<int>& fs, const Context& ctx, BayesTree<D>* tree) {
  for (int f : fs) {
    const int start = startClique(f, ctx, *tree);
    if (start < 0 || !withinBudget(f, start, ctx, *tree)) return -1;
  }
  int updated = 0;
  const auto own = [&](int f) { return ctx.factors.factors[f].custom() != nullptr; };
  if (std::none_of(fs.begin(), fs.end(), own)) {  // built-ins cannot fail: linearised on the way
    for (int f : fs) updated += foldIn(f, ctx, tree);
    return updated;
  }
  // Every factor linearised before the first changes the tree: a failing factor of your own
  // throws (FactorError) with the tree as it was.
  linearized_.resize(fs.size());
  for (size_t k = 0; k < fs.size(); ++k) {
    try {
      ctx.factors.factors[fs[k]].linearizeWeighted(ctx.theta, &linearized_[k]);
    } catch (...) {
      throwFactorError(factorText(ctx.factors.factors[fs[k]], fs[k], ctx.theta), fs[k]);
    }
  }
  for (size_t k = 0; k < fs.size(); ++k) updated += foldIn(fs[k], &linearized_[k], ctx, tree);
  return updated;
}

template <class G>
int FoldIn<G>::foldInAll(int first, const Context& ctx, BayesTree<D>* tree) {
  std::vector<int> fs;
  for (int f = first; f < ctx.factors.numFactors(); ++f) fs.push_back(f);
  return foldInAll(fs, ctx, tree);
}

template <class G>
int FoldIn<G>::foldIn(int f, const Context& ctx, BayesTree<D>* tree) {
  return foldIn(f, nullptr, ctx, tree);
}

template <class G>
int FoldIn<G>::foldIn(int f, const typename Factor<G>::Linearization* linearized,
                      const Context& ctx, BayesTree<D>* tree) {
  auto& cliques = tree->cliques;
  std::vector<int>& slot = ctx.slot;
  const Factor<G>& e = ctx.factors.factors[f];
  const int start = startClique(f, ctx, *tree);
  int later;
  separatorsToExtend(f, start, ctx, *tree, &later, &path_);
  for (int c : path_) {  // each separator grows by one variable: its flops and doubles with it
    const size_t nf = cliques[c].frontals.size(), ns = cliques[c].separator.size();
    tree->countClique(nf, ns, -1.0, cliques[c].cached);
    tree->countClique(nf, ns + 1, 1.0, cliques[c].cached);
    cliques[c].extendSeparator(later, &extend_buf_);
  }
  // W over the start clique's variables and the right-hand side: [Aᵀ; −rᵀ] (a local A: the
  // compiler keeps it apart from W's buffer).
  typename Factor<G>::Linearization A;
  if (linearized != nullptr)
    A = *linearized;
  else
    e.linearizeWeighted(ctx.theta, &A);
  using MatMap = Eigen::Map<Eigen::MatrixXd>;
  int rows = cliques[start].F + cliques[start].Sn + 1;
  {
    const Clique<D>& c = cliques[start];
    w_buf_.resize(static_cast<size_t>(rows) * D);
    MatMap W(w_buf_.data(), rows, D);
    W.setZero();
    BayesTree<D>::setSlots(c, &slot);
    for (int k = 0; k < e.arity(); ++k)
      if (!ctx.fixed[e.key(k)]) W.middleRows(slot[e.key(k)] * D, D) = A.A[k].transpose();
    BayesTree<D>::clearSlots(c, &slot);
    W.row(rows - 1) = -A.r.transpose();
  }
  int updated = 0;
  for (int id = start;;) {
    Clique<D>& c = cliques[id];
    const int Sn = c.Sn;
    c.rankUpdate(w_buf_.data(), rows);  // leaves V = rows F..F+Sn of W
    ++updated;
    if (c.parent < 0) break;  // what is left is the constant term
    const auto V = MatMap(w_buf_.data(), rows, D).bottomRows(Sn + 1);
    // The parent's W: V scattered to the parent's rows.
    const Clique<D>& p = cliques[c.parent];
    const int Np = p.F + p.Sn;
    BayesTree<D>::setSlots(p, &slot);
    w_parent_buf_.resize(static_cast<size_t>(Np + 1) * D);
    MatMap Wp(w_parent_buf_.data(), Np + 1, D);
    Wp.setZero();
    for (int b = 0; b < static_cast<int>(c.separator.size()); ++b)
      Wp.middleRows(slot[c.separator[b]] * D, D) = V.middleRows(b * D, D);
    Wp.row(Np) = V.row(Sn);
    BayesTree<D>::clearSlots(p, &slot);
    w_buf_.swap(w_parent_buf_);
    rows = Np + 1;
    id = c.parent;
  }
  return updated;
}

template <class G>
bool FoldIn<G>::worthFolding(const std::vector<Factor<G>>& factors, const std::vector<char>& fixed,
                             BayesTree<D>* tree) {
  if (factors.empty()) return false;
  std::vector<int> starts;
  double fold_flops = 0;
  for (const Factor<G>& e : factors) {
    int start = -1;
    for (int k = 0; k < e.arity(); ++k) {
      const int v = e.key(k);
      if (!fixed[v] && tree->clique_of[v] >= 0 &&
          (start < 0 || tree->isAncestorOrSelf(start, tree->clique_of[v])))
        start = tree->clique_of[v];
    }
    if (start < 0) return false;  // both ends new: no path to compare
    starts.push_back(start);
    fold_flops += foldFlops(start, *tree);
  }
  return fold_flops <= eliminationFlops(starts, tree);
}

template <class G>
std::vector<Factor<G>> FoldIn<G>::splitOffIntroducing(std::vector<Factor<G>>* queued,
                                                      const std::vector<char>& fixed,
                                                      const BayesTree<D>& tree,
                                                      std::vector<int>* slot) {
  std::vector<Factor<G>> intro, rest;
  std::vector<char> placed(queued->size(), 0);
  std::vector<int> joined;  // new poses joined by a factor in `intro` (slot[v] = 1)
  auto known = [&](int v) { return fixed[v] || tree.clique_of[v] >= 0 || (*slot)[v] == 1; };
  for (bool progress = true; progress;) {
    progress = false;
    for (size_t k = 0; k < queued->size(); ++k) {
      if (placed[k]) continue;
      const Factor<G>& e = (*queued)[k];
      const bool ki = known(e.key(0)), kj = e.arity() < 2 || known(e.key(1));
      if (ki && kj) {
        rest.push_back(e);
      } else if (e.arity() == 2 && (ki || kj) && e.inlierWeight() > 0) {
        // (A factor of weight 0 brings no information: it never introduces a pose, whose
        // clique would be singular in the first pass; it waits for the pose to be known.)
        const int v = ki ? e.key(1) : e.key(0);
        (*slot)[v] = 1;
        joined.push_back(v);
        intro.push_back(e);
      } else {
        continue;
      }
      placed[k] = 1;
      progress = true;
    }
  }
  for (size_t k = 0; k < queued->size(); ++k)
    if (!placed[k]) intro.push_back((*queued)[k]);
  for (int v : joined) (*slot)[v] = -1;
  queued->swap(intro);
  return rest;
}

template <class G>
size_t FoldIn<G>::scratchBytes() const {
  return (extend_buf_.capacity() + w_buf_.capacity() + w_parent_buf_.capacity()) * sizeof(double);
}

template class FoldIn<SE2>;
template class FoldIn<SE3>;

}  // namespace arbor::bayestree
