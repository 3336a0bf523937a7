#include "arbor_slam/bayestree/top_elimination.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <memory>

#include "arbor_slam/bayestree/tree_shape.h"

namespace arbor::bayestree {
namespace {

// An elimination with fewer flops off its critical path stays on one thread (a helper's
// wake-up and the hand-over would cost more than they save, tens of microseconds; tuned on
// smallGrid3D, torus3D, parking-garage).
constexpr double kMinSharedElimination = 1e6;

}  // namespace

template <class G>
void TopElimination<G>::assemble(const Clique<D>& c, int lane, const std::vector<char>& fixed,
                                 BayesTree<D>* tree, const LinearizedFactors<G>& factors,
                                 UpdateThreads* threads) {
  for (int ch : c.children) tree->cliques[ch].applyPending();
  const int nf = static_cast<int>(c.frontals.size());
  const int N = c.F + c.Sn;
  std::vector<int>& slot = threads->lanes[lane].slot;
  std::vector<int>& child_slots = threads->lanes[lane].child_slots;
  DoubleBuffer& h_buf = threads->lanes[lane].h;
  BayesTree<D>::setSlots(c, &slot);
  const int lda = N + 1;
  h_buf.resize(static_cast<size_t>(lda) * lda);
  for (int j = 0; j < lda; ++j)  // only the lower triangle is used
    std::fill(h_buf.data() + static_cast<size_t>(j) * lda + j, h_buf.data() + (j + 1) * lda, 0.0);
  Eigen::Map<Eigen::MatrixXd> H(h_buf.data(), N + 1, N + 1);
  // The factors whose first eliminated variable is a frontal of this clique: H(p, q) and g_p
  // for every pair of their non-fixed keys (a fixed key is a constant).
  for (int a = 0; a < nf; ++a) {
    const int v = c.frontals[a];
    for (int f : factors.var_factors[v]) {
      const Factor<G>& e = factors.factors[f];
      if (!LinearizedFactors<G>::assembledAt(e, v, slot, fixed)) continue;
      const auto& L = factors.lin[f];
      const int arity = e.arity();
      for (int k = 0; k < arity; ++k) {
        if (fixed[e.key(k)]) continue;
        const int sk = slot[e.key(k)] * D;
        H.row(N).template segment<D>(sk) += L.g[k].transpose();
        for (int l = 0; l < arity; ++l) {
          if (fixed[e.key(l)]) continue;
          const int sl = slot[e.key(l)] * D;
          if (sk >= sl) H.template block<D, D>(sk, sl) += L.at(k, l);  // lower triangle
        }
      }
    }
  }
  // The children's cached factors on their separators.
  for (int ch : c.children) {
    const Clique<D>& k = tree->cliques[ch];
    const int m = static_cast<int>(k.separator.size());
    child_slots.resize(m);
    for (int p = 0; p < m; ++p) child_slots[p] = slot[k.separator[p]] * D;
    const auto kH = k.cachedH();
    const auto kg = k.cachedG();
    // kH holds its lower triangle (and full diagonal blocks).
    for (int q = 0; q < m; ++q) {
      const int sq = child_slots[q];
      H.row(N).template segment<D>(sq) += kg.template segment<D>(q * D).transpose();
      for (int p = 0; p < m; ++p) {
        const int sp = child_slots[p];
        if (sp < sq) continue;
        if (p >= q)
          H.template block<D, D>(sp, sq) += kH.template block<D, D>(p * D, q * D);
        else
          H.template block<D, D>(sp, sq) += kH.template block<D, D>(q * D, p * D).transpose();
      }
    }
  }
  BayesTree<D>::clearSlots(c, &slot);
}

template <class G>
bool TopElimination<G>::eliminateClique(int id, int lane, const std::vector<char>& fixed,
                                        BayesTree<D>* tree, const LinearizedFactors<G>& factors,
                                        UpdateThreads* threads) {
  Clique<D>& c = tree->cliques[id];
  c.allocate();
  const int F = c.F, Sn = c.Sn, N = F + Sn, lda = N + 1;
  assemble(c, lane, fixed, tree, factors, threads);
  double* A = threads->lanes[lane].h.data();
  std::vector<double>& diag_buf = threads->lanes[lane].diag;
  diag_buf.resize(F);
  for (int k = 0; k < F; ++k) diag_buf[k] = A[static_cast<size_t>(k) * lda + k];
  bool damped = false;
  if (!partialCholesky(A, lda, F, N + 1, diag_buf.data())) {
    damped = true;
    double max_diag = 0;
    bool finite = true;
    for (int k = 0; k < F; ++k) {
      finite = finite && std::isfinite(diag_buf[k]);
      if (std::isfinite(diag_buf[k])) max_diag = std::max(max_diag, diag_buf[k]);
    }
    const double floor = std::max(1e-9 * max_diag, 1e-9);
    std::vector<double> base(F), damped_diag(F);
    for (int k = 0; k < F; ++k)
      base[k] = std::isfinite(diag_buf[k]) ? std::max(diag_buf[k], floor) : floor;
    bool ok = false;
    for (double lambda = 1e-6; lambda < 1e6 && !ok && finite; lambda *= 10) {
      assemble(c, lane, fixed, tree, factors, threads);
      for (int k = 0; k < F; ++k) {
        A[static_cast<size_t>(k) * lda + k] += lambda * base[k];
        damped_diag[k] = A[static_cast<size_t>(k) * lda + k];
      }
      ok = partialCholesky(A, lda, F, N + 1, damped_diag.data());
    }
    if (!ok) {  // not even damping helps (non-finite input): pin the frontals at zero
      std::fill(c.storage.begin(), c.storage.end(), 0.0);
      for (int k = 0; k < F; ++k) c.lsPtr()[static_cast<size_t>(k) * c.ld + k] = std::sqrt(floor);
      c.dirty = true;
      c.damped = true;
      dropChildrenCachedFactors(c, tree);
      return true;
    }
  }
  // Copy out: LS = first F columns (rows 0..N−1), d = row N of them, the Schur complement.
  double* LS = c.lsPtr();
  for (int k = 0; k < F; ++k) {
    const double* col = A + static_cast<size_t>(k) * lda;
    double* out = LS + static_cast<size_t>(k) * c.ld;
    for (int i = 0; i < k; ++i) out[i] = 0.0;
    std::copy(col + k, col + N, out + k);
    c.dPtr()[k] = col[N];
  }
  double* cH = c.hPtr();
  double* cg = c.gPtr();
  for (int q = 0; q < Sn; ++q) {  // the lower triangle, then the diagonal blocks made full
    const double* col = A + static_cast<size_t>(F + q) * lda + F;
    std::copy(col + q, col + Sn, cH + static_cast<size_t>(q) * c.ldh + q);
    cg[q] = col[Sn];
  }
  for (int b = 0; b < Sn; b += D)
    for (int q = b; q < b + D; ++q)
      for (int p = b; p < q; ++p)
        cH[static_cast<size_t>(q) * c.ldh + p] = cH[static_cast<size_t>(p) * c.ldh + q];
  c.dirty = true;
  c.damped = damped;
  dropChildrenCachedFactors(c, tree);
  return damped;
}

template <class G>
void TopElimination<G>::dropChildrenCachedFactors(const Clique<D>& c, BayesTree<D>* tree) {
  for (int ch : c.children) tree->cliques[ch].dropCachedFactor();
}

template <class G>
typename TopElimination<G>::Output TopElimination<G>::run(const Input& in, BayesTree<D>* tree,
                                                          LinearizedFactors<G>* factors,
                                                          UpdateThreads* threads) {
  Output out;
  const std::vector<int>& top = in.top;
  const std::vector<int>& orphans = in.orphans;
  const std::vector<char>& fixed = in.fixed;
  const int n = static_cast<int>(top.size());
  if (n == 0) {
    factors->linearizeAll(in.to_linearize, in.theta, threads);
    return out;
  }
  std::vector<int>& slot = threads->lanes[0].slot;
  std::vector<Clique<D>>& cliques = tree->cliques;
  for (int a = 0; a < n; ++a) slot[top[a]] = a;
  RowList& rows = rows_;
  rows.clear();
  // Alg. 4 step 2's factors, for the structure: those with two or more non-fixed keys in the
  // top, once each (from their first key in the top's order; a unary factor adds no structure).
  for (int a = 0; a < n; ++a) {
    const int v = top[a];
    for (int f : factors->var_factors[v]) {
      const Factor<G>& e = factors->factors[f];
      int keys = 0;
      bool first = true;
      for (int k = 0; k < e.arity(); ++k) {
        const int o = e.key(k);
        if (fixed[o]) continue;
        ++keys;
        if (slot[o] < a) first = false;  // a key outside the top has slot −1: not first
      }
      if (keys < 2 || !first) continue;
      for (int k = 0; k < e.arity(); ++k)
        if (!fixed[e.key(k)]) rows.add(slot[e.key(k)]);
      rows.endRow();
    }
  }
  // Alg. 4 step 3, "Add cached linear factors from orphans T_O".
  for (int oc : orphans) {
    for (int v : cliques[oc].separator) rows.add(slot[v]);
    rows.endRow();
  }
  // Alg. 4 step 4, "Re-order variables" (constrained, iSAM2's incremental variable ordering: the
  // variables of the new factors last), side by side with the linearisation of the relinearised
  // factors (Alg. 4 step 2), which the ordering and the symbolic elimination do not read.
  std::vector<int>& group = group_;
  group.assign(n, 0);
  if (in.last_group)
    for (int a = 0; a < n; ++a) group[a] = (*in.last_group)[top[a]] ? 1 : 0;
  EliminationPlan plan;
  factors->linearizeAll(in.to_linearize, in.theta, threads, [&] {
    plan = planTop<D>(n, rows, group, in.nested_dissection_min, in.nested_dissection_try_flops);
  });

  // Alg. 4 step 5, "Eliminate the factor graph (Alg. 1) and create a new Bayes tree (Alg. 2)":
  // the cliques of the plan, then their numeric elimination below.
  const int m = static_cast<int>(plan.cliques.size());
  std::vector<int>& ids = ids_;
  ids.resize(m);
  for (int k = 0; k < m; ++k) ids[k] = tree->allocClique();
  // The tree this elimination makes, every cached factor kept, decides whether any is dropped.
  const bool dropping =
      tree->dropsCachedFactors(tree->doubles + treeShape<D>(plan, 0).allKeptDoubles());
  for (int k = 0; k < m; ++k) {
    const SymbolicClique& sc = plan.cliques[k];
    Clique<D>& c = cliques[ids[k]];
    c.frontals.clear();
    c.separator.clear();
    c.children.clear();
    for (int a : sc.frontals) c.frontals.push_back(top[a]);
    for (int a : sc.separator) c.separator.push_back(top[a]);
    c.parent = sc.parent < 0 ? -1 : ids[sc.parent];
    for (int v : c.frontals) tree->clique_of[v] = ids[k];
    c.cached = !dropping || tree->keepsCachedFactor(c.frontals.size(), c.separator.size());
    tree->countClique(c);
    out.flops += BayesTree<D>::cliqueFlops(c.frontals.size(), c.separator.size());
  }
  // Recycled cliques keep their storage: hand the largest buffers to the largest new cliques
  // (saves reallocating, and re-faulting, the big ones on every update).
  if (m > 1) {
    by_need_.assign(ids.begin(), ids.end());
    by_capacity_.assign(ids.begin(), ids.end());
    auto need = [&](int id) {
      const Clique<D>& c = cliques[id];
      const int F = static_cast<int>(c.frontals.size()) * D;
      const int Sn = static_cast<int>(c.separator.size()) * D;
      return Clique<D>::sizeFor(F, F + Sn, Sn);
    };
    std::sort(by_need_.begin(), by_need_.end(), [&](int a, int b) { return need(a) > need(b); });
    std::sort(by_capacity_.begin(), by_capacity_.end(), [&](int a, int b) {
      return cliques[a].storage.capacity() > cliques[b].storage.capacity();
    });
    buffers_.resize(m);
    for (int k = 0; k < m; ++k) buffers_[k].swap(cliques[by_capacity_[k]].storage);
    for (int k = 0; k < m; ++k) cliques[by_need_[k]].storage.swap(buffers_[k]);
  }
  for (int k = 0; k < m; ++k) {
    const int parent = cliques[ids[k]].parent;
    if (parent < 0)
      tree->roots.push_back(ids[k]);
    else
      cliques[parent].children.push_back(ids[k]);
  }
  // Alg. 4 step 6, "Insert the orphans T_O back into the new Bayes tree": each hangs below the
  // clique where the first eliminated variable of its separator is frontal.
  for (int oc : orphans) {
    int first = n;
    for (int v : cliques[oc].separator) first = std::min(first, plan.position[slot[v]]);
    tree->attachOrphan(oc, ids[plan.clique_of_variable[plan.order[first]]]);
  }
  for (int a = 0; a < n; ++a) slot[top[a]] = -1;
  for (int k = 0; k < m; ++k) {  // children (new ones, and orphans) before parents
    Clique<D>& c = cliques[ids[k]];
    const double F = static_cast<double>(c.frontals.size()) * D;
    c.subtree_entries = F * (F + static_cast<double>(c.separator.size()) * D);
    for (int ch : c.children) c.subtree_entries += cliques[ch].subtree_entries;
  }
  // The numeric elimination, children before parents: a clique is ready once its last child is
  // done, and independent subtrees go to different threads.
  std::unique_ptr<std::atomic<int>[]> children_left(new std::atomic<int>[m]);
  for (int k = 0; k < m; ++k) children_left[k].store(0, std::memory_order_relaxed);
  for (int k = 0; k < m; ++k)
    if (plan.cliques[k].parent >= 0)
      children_left[plan.cliques[k].parent].fetch_add(1, std::memory_order_relaxed);
  std::vector<int>& leaves = threads->ready;
  leaves.clear();
  for (int k = m - 1; k >= 0; --k)
    if (children_left[k].load(std::memory_order_relaxed) == 0) leaves.push_back(k);
  for (Lane& l : threads->lanes) l.eliminated = l.indeterminate = 0;
  const LinearizedFactors<G>& lin = *factors;
  threads->workers.run(
      leaves,
      [&](int lane, int k) {
        ++threads->lanes[lane].eliminated;
        if (eliminateClique(ids[k], lane, fixed, tree, lin, threads))
          ++threads->lanes[lane].indeterminate;
        const int parent = plan.cliques[k].parent;
        return parent >= 0 && children_left[parent].fetch_sub(1, std::memory_order_acq_rel) == 1
                   ? parent
                   : -1;
      },
      /*share=*/offCriticalPathFlops(plan) >= kMinSharedElimination);
  for (size_t l = 0; l < threads->lanes.size(); ++l) {
    out.indeterminate += threads->lanes[l].indeterminate;
    if (l > 0) out.on_helpers += threads->lanes[l].eliminated;
  }
  out.cliques = m;
  out.variables = n;
  return out;
}

// The flops of eliminating `plan` (F³/3 + F²·S + F·S² per clique) that lie off its critical path
// (the costliest chain from a leaf to a root): what a second thread could take on.
template <class G>
double TopElimination<G>::offCriticalPathFlops(const EliminationPlan& plan) {
  const int m = static_cast<int>(plan.cliques.size());
  std::vector<double>& chain = chain_flops_;
  chain.assign(m, 0.0);
  double total = 0, critical = 0;
  for (int k = 0; k < m; ++k) {  // children before parents
    const SymbolicClique& c = plan.cliques[k];
    const double F = static_cast<double>(c.frontals.size()) * D;
    const double S = static_cast<double>(c.separator.size()) * D;
    const double flops = F * F * F / 3 + F * F * S + F * S * S;
    total += flops;
    chain[k] += flops;
    critical = std::max(critical, chain[k]);
    if (c.parent >= 0) chain[c.parent] = std::max(chain[c.parent], chain[k]);
  }
  return total - critical;
}

template <class G>
size_t TopElimination<G>::scratchBytes() const {
  size_t bytes = 0;
  for (const auto& b : buffers_) bytes += b.capacity() * sizeof(double);
  return bytes;
}

template class TopElimination<SE2>;
template class TopElimination<SE3>;

}  // namespace arbor::bayestree
