#include "arbor_slam/bayestree/relinearization_swap.h"

#include <algorithm>
#include <utility>

namespace arbor::bayestree {

template <class G>
SwapBase<G> baseOfJob(RelinearizationSnapshot<G>&& snap, RelinearizedTree<G>&& job) {
  SwapBase<G> b;
  b.n = static_cast<int>(snap.theta.size());
  b.f = static_cast<int>(snap.factors.size());
  b.fixed = std::move(snap.fixed);
  if (job.iterations > 1) {
    // Every pose stepped: Θ before is the smoother's at the snapshot (M's before Θ_M ⊕ Δ_M).
    std::vector<G> before = std::move(snap.theta);
    for (size_t k = 0; k < snap.relinearized.size(); ++k)
      before[static_cast<size_t>(snap.relinearized[k])] = snap.theta_before[k];
    b.theta = std::move(job.theta);
    b.all_relinearized = true;
    b.theta_before = std::move(before);
  } else {
    b.theta = std::move(snap.theta);
    b.relinearized = std::move(snap.relinearized);
    b.theta_before = std::move(snap.theta_before);
  }
  b.tree = std::move(job.tree);
  b.factors = std::move(job.factors);
  b.solve = std::move(job.solve);
  b.delta = std::move(job.delta);
  return b;
}

template <class G>
Rebased<G> rebase(SwapBase<G>&& base, const SwapSource<G>& src) {
  const int n = static_cast<int>(src.theta.size());
  Rebased<G> r;
  // Θ: the base's, moved since as src's poses were (θ ← T θ for every move, i.e.
  // θ_now θ_then⁻¹ on the left; a pose not relinearised had θ_then = the base's).
  r.theta = std::move(base.theta);
  std::vector<int> moved_poses = src.since.moved;
  std::sort(moved_poses.begin(), moved_poses.end());
  moved_poses.erase(std::unique(moved_poses.begin(), moved_poses.end()), moved_poses.end());
  for (int v : moved_poses) {
    if (v >= base.n) continue;
    const G* before = nullptr;
    if (base.all_relinearized) {
      before = &base.theta_before[v];
    } else {
      const auto it = std::lower_bound(base.relinearized.begin(), base.relinearized.end(), v);
      if (it != base.relinearized.end() && *it == v)
        before = &base.theta_before[static_cast<size_t>(it - base.relinearized.begin())];
    }
    if (!before) {
      r.theta[v] = src.theta[v];
      continue;
    }
    r.theta[v] = src.theta[v].compose(before->inverse()).compose(r.theta[v]);
    r.theta[v].normalize();
  }
  for (int v = base.n; v < n; ++v) r.theta.push_back(src.theta[v]);
  // The factors added since go first in the queue (their indices stay), with the weights they
  // have now.
  r.queued.assign(src.factors.factors.begin() + base.f, src.factors.factors.end());
  if (src.queued) r.queued.insert(r.queued.end(), src.queued->begin(), src.queued->end());
  std::vector<std::pair<int, double>> weights;
  for (int f : src.since.reweighted)
    if (f < base.f) weights.emplace_back(f, src.factors.factors[f].inlierWeight());
  for (int f : src.to_relinearize)
    if (f < base.f) r.to_relinearize.push_back(f);
  r.tree = std::move(base.tree);
  r.factors = std::move(base.factors);
  r.solve = std::move(base.solve);
  r.delta = std::move(base.delta);
  for (int v = base.n; v < n; ++v) {
    r.tree.addVariable();
    r.factors.addVariable();
    r.solve.addVariable();
    r.delta.push_back(G::Tangent::Zero());
  }
  const std::vector<char>& fixed = src.fixed;
  LinearizedFactors<G>& factors = r.factors;
  auto touchKeys = [&](const Factor<G>& e) {
    for (int k = 0; k < e.arity(); ++k)
      if (!fixed[e.key(k)]) r.touch.push_back(e.key(k));
  };
  auto relinearizeFactor = [&](int f) {
    r.to_relinearize.push_back(f);
    touchKeys(factors.factors[f]);
  };
  // A reweighting takes the base's factor in or out of the structure as setFactorWeight does
  // (LinearizedFactors::attached follows the weight the base had).
  for (const auto& [f, w] : weights) {
    factors.factors[f].setInlierWeight(w);
    if (w > 0 && !factors.attached[f]) {
      r.readmitted.push_back(f);
    } else if (w > 0) {
      relinearizeFactor(f);
    } else if (factors.attached[f]) {
      factors.detach(f);
      touchKeys(factors.factors[f]);
    }
  }
  for (int v : moved_poses)
    if (v < base.n)
      for (int f : factors.var_factors[v]) relinearizeFactor(f);
  // The variables the base held fixed that are not (not in its tree, or released since), and
  // every variable added since: new to the base's tree.
  for (int v = 0; v < base.n; ++v) {
    if (!base.fixed[v] || fixed[v]) continue;
    r.new_vars.push_back(v);
    for (int f : factors.var_factors[v]) {
      const Factor<G>& e = factors.factors[f];
      for (int k = 0; k < e.arity(); ++k)
        if (e.key(k) != v && !fixed[e.key(k)]) r.touch.push_back(e.key(k));
    }
  }
  for (int v = base.n; v < n; ++v)
    if (!fixed[v]) r.new_vars.push_back(v);
  return r;
}

template <class G>
std::vector<int> holdUnattached(Rebased<G>* r) {
  std::vector<char> has_factor(r->theta.size(), 0);
  for (const Factor<G>& e : r->queued)
    if (e.inlierWeight() > 0)
      for (int k = 0; k < e.arity(); ++k) has_factor[e.key(k)] = 1;
  std::vector<int> kept, held;
  for (int v : r->new_vars) {
    bool attached = has_factor[v] != 0;
    for (int f : r->factors.var_factors[v])
      if (r->factors.attached[f] || r->factors.factors[f].inlierWeight() > 0) attached = true;
    (attached ? kept : held).push_back(v);
  }
  r->new_vars = std::move(kept);
  return held;
}

template SwapBase<SE2> baseOfJob(RelinearizationSnapshot<SE2>&&, RelinearizedTree<SE2>&&);
template SwapBase<SE3> baseOfJob(RelinearizationSnapshot<SE3>&&, RelinearizedTree<SE3>&&);
template Rebased<SE2> rebase(SwapBase<SE2>&&, const SwapSource<SE2>&);
template Rebased<SE3> rebase(SwapBase<SE3>&&, const SwapSource<SE3>&);
template std::vector<int> holdUnattached(Rebased<SE2>*);
template std::vector<int> holdUnattached(Rebased<SE3>*);

}  // namespace arbor::bayestree
