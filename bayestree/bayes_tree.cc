#include "arbor_slam/bayestree/bayes_tree.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "arbor_slam/core/factor.h"

namespace arbor::bayestree {

template <int D>
int BayesTree<D>::allocClique() {
  ++num_cliques;
  if (!free_cliques.empty()) {
    const int id = free_cliques.back();
    free_cliques.pop_back();
    cliques[id].in_use = true;
    cliques[id].removed_stamp = -1;
    return id;
  }
  cliques.emplace_back();
  cliques.back().in_use = true;
  return static_cast<int>(cliques.size()) - 1;
}

template <int D>
void BayesTree<D>::freeClique(int id) {
  --num_cliques;
  CliqueD& c = cliques[id];
  c.frontals.clear();
  c.separator.clear();
  c.children.clear();
  c.parent = -1;
  c.dirty = false;
  if (!c.unseen.empty()) clearUnseen(id);
  c.damped = false;
  c.cached = true;
  c.in_use = false;
  c.pending.resize(0, 0);
  c.pending_cols = 0;
  free_cliques.push_back(id);
  freed_since_release_.push_back(id);
}

template <int D>
void BayesTree<D>::releaseFreeStorage() {
  for (int c : freed_since_release_)
    if (!cliques[c].in_use) cliques[c].storage.fit(0);
  freed_since_release_.clear();
}

template <int D>
bool BayesTree<D>::isAncestorOrSelf(int ancestor, int c) const {
  for (; c >= 0; c = cliques[c].parent)
    if (c == ancestor) return true;
  return false;
}

template <int D>
void BayesTree<D>::addUnseen(int id, int v) {
  std::vector<int>& unseen = cliques[id].unseen;
  if (unseen.empty()) {
    ++num_deferred;
    deferred.push_back(id);
  } else if (std::find(unseen.begin(), unseen.end(), v) != unseen.end()) {
    return;
  }
  unseen.push_back(v);
}

template <int D>
void BayesTree<D>::clearUnseen(int id) {
  if (cliques[id].unseen.empty()) return;
  cliques[id].unseen.clear();
  --num_deferred;
}

template <int D>
void BayesTree<D>::clearAllUnseen() {
  for (int id : deferred)
    if (id < static_cast<int>(cliques.size())) clearUnseen(id);
  deferred.clear();
}

template <int D>
void BayesTree<D>::cliquesContaining(const std::vector<int>& vars, std::vector<int>* marked) {
  std::vector<int>& stack = stack_;
  stack.clear();
  for (int v : vars) {
    stack.push_back(clique_of[v]);
    while (!stack.empty()) {
      const int c = stack.back();
      stack.pop_back();
      marked->push_back(c);
      for (int ch : cliques[c].children) {
        const auto& sep = cliques[ch].separator;
        if (std::find(sep.begin(), sep.end(), v) != sep.end()) stack.push_back(ch);
      }
    }
  }
}

template <int D>
void BayesTree<D>::removeTop(const std::vector<int>& marked, Top* top) {
  const int stamp = ++remove_stamp_;
  removed_.clear();
  for (int c : marked)
    while (c >= 0 && cliques[c].removed_stamp != stamp) {
      cliques[c].removed_stamp = stamp;
      removed_.push_back(c);
      c = cliques[c].parent;
    }
  for (size_t k = 0; k < removed_.size(); ++k) {  // grows by the children without a cached factor
    const CliqueD& c = cliques[removed_[k]];
    countClique(c.frontals.size(), c.separator.size(), -1.0, c.cached);
    for (int v : c.frontals) top->variables.push_back(v);
    for (int ch : c.children) {
      if (cliques[ch].removed_stamp == stamp) continue;
      if (cliques[ch].cached) {
        top->orphans.push_back(ch);
      } else {
        cliques[ch].removed_stamp = stamp;
        removed_.push_back(ch);
      }
    }
  }
  if (removed_.empty()) return;
  // Deferred solves of removed cliques: an orphan that holds one of their unseen variables in
  // its separator has not seen its move either (running intersection: it lies below the
  // clique that deferred it), so it inherits it.
  unseen_.clear();
  for (int c : removed_)
    unseen_.insert(unseen_.end(), cliques[c].unseen.begin(), cliques[c].unseen.end());
  if (!unseen_.empty()) {
    std::sort(unseen_.begin(), unseen_.end());
    unseen_.erase(std::unique(unseen_.begin(), unseen_.end()), unseen_.end());
    for (int o : top->orphans)
      for (int v : cliques[o].separator)
        if (std::binary_search(unseen_.begin(), unseen_.end(), v)) addUnseen(o, v);
  }
  roots.erase(std::remove_if(roots.begin(), roots.end(),
                             [&](int r) { return cliques[r].removed_stamp == stamp; }),
              roots.end());
  for (int c : removed_) freeClique(c);
}

template <int D>
void BayesTree<D>::attachOrphan(int orphan, int parent) {
  cliques[orphan].parent = parent;
  cliques[parent].children.push_back(orphan);
}

template <int D>
template <class Factor>
void BayesTree<D>::checkInvariants(const std::vector<Factor>& factors,
                                   const std::vector<char>& attached,
                                   const std::vector<char>& fixed,
                                   const std::function<bool(int)>& awaiting) const {
  auto fail = [](const std::string& what) {
    throw std::logic_error("Bayes tree invariant: " + what);
  };
  const int n = static_cast<int>(clique_of.size());
  const int nc = static_cast<int>(cliques.size());
  std::vector<int> frontal_count(n, 0);
  int in_use = 0;
  for (int id = 0; id < nc; ++id) {
    const CliqueD& c = cliques[id];
    if (!c.in_use) continue;
    ++in_use;
    const std::string name = "clique " + std::to_string(id);
    if (c.frontals.empty()) fail(name + " has no frontal variable");
    const int nf = static_cast<int>(c.frontals.size()), ns = static_cast<int>(c.separator.size());
    if (c.F != nf * D || c.Sn != ns * D || c.ld < c.F + c.Sn ||
        (c.cached ? c.ldh < c.Sn : c.ldh != 0) ||
        c.storage.size() != CliqueD::sizeFor(c.F, c.ld, c.ldh))
      fail(name + " has matrices of the wrong size");
    if (!c.cached && c.pending_cols != 0) fail(name + " has pending updates but no cached factor");
    for (int v : c.frontals) {
      if (v < 0 || v >= n || fixed[v]) fail(name + " has a bad frontal " + std::to_string(v));
      if (++frontal_count[v] > 1)
        fail("variable " + std::to_string(v) + " is frontal in more than one clique (" + name +
             " and clique " + std::to_string(clique_of[v]) + ")");
      if (clique_of[v] != id) fail("clique_of[" + std::to_string(v) + "] is not " + name);
      if (std::find(c.separator.begin(), c.separator.end(), v) != c.separator.end())
        fail(name + ": variable " + std::to_string(v) + " both frontal and separator");
    }
    if (c.parent < 0) {
      if (!c.separator.empty()) fail("root " + name + " has a non-empty separator");
      if (std::find(roots.begin(), roots.end(), id) == roots.end())
        fail(name + " has no parent but is not a root");
    } else {
      if (c.parent >= nc || !cliques[c.parent].in_use) fail(name + " has a dead parent");
      const CliqueD& p = cliques[c.parent];
      if (std::find(p.children.begin(), p.children.end(), id) == p.children.end())
        fail(name + " is not among its parent's children");
      // Running intersection: the separator lies in the parent's frontals ∪ separator.
      for (int v : c.separator)
        if (std::find(p.frontals.begin(), p.frontals.end(), v) == p.frontals.end() &&
            std::find(p.separator.begin(), p.separator.end(), v) == p.separator.end())
          fail(name + ": separator variable " + std::to_string(v) + " not in parent clique " +
               std::to_string(c.parent) + " (running intersection)");
      if (c.separator.empty()) fail(name + " has a parent but an empty separator");
    }
    for (int ch : c.children)
      if (ch < 0 || ch >= nc || !cliques[ch].in_use || cliques[ch].parent != id)
        fail(name + ": child " + std::to_string(ch) + " does not point back");
    // Acyclic: the root is reached within nc steps.
    int steps = 0;
    for (int p = c.parent; p >= 0; p = cliques[p].parent)
      if (++steps > nc) fail(name + " lies on a parent cycle");
  }
  if (in_use != num_cliques) fail("clique count mismatch");
  // Deferred solves: counted, listed, and unseen variables are separator variables.
  int deferred_count = 0;
  std::vector<char> listed(static_cast<size_t>(nc), 0);
  for (int id : deferred)
    if (id >= 0 && id < nc) listed[id] = 1;
  for (int id = 0; id < nc; ++id) {
    const CliqueD& c = cliques[id];
    if (c.unseen.empty()) continue;
    if (!c.in_use) fail("free clique " + std::to_string(id) + " has unseen variables");
    ++deferred_count;
    if (!listed[id]) fail("deferred clique " + std::to_string(id) + " is not listed");
    for (int v : c.unseen)
      if (std::find(c.separator.begin(), c.separator.end(), v) == c.separator.end())
        fail("clique " + std::to_string(id) + " has unseen variable " + std::to_string(v) +
             " outside its separator");
  }
  if (deferred_count != num_deferred) fail("deferred count mismatch");
  double sum_flops = 0, sum_doubles = 0;
  for (const CliqueD& c : cliques)
    if (c.in_use) {
      sum_flops += cliqueFlops(c.frontals.size(), c.separator.size());
      sum_doubles += cliqueDoubles(c.frontals.size(), c.separator.size(), c.cached);
    }
  if (std::abs(sum_flops - flops) > 1e-9 * std::max(1.0, sum_flops))
    fail("flops " + std::to_string(flops) + " is not the cliques' sum " +
         std::to_string(sum_flops));
  if (std::abs(sum_doubles - doubles) > 1e-9 * std::max(1.0, sum_doubles))
    fail("doubles " + std::to_string(doubles) + " is not the cliques' sum " +
         std::to_string(sum_doubles));
  for (int r : roots)
    if (r < 0 || r >= nc || !cliques[r].in_use || cliques[r].parent != -1)
      fail("root " + std::to_string(r) + " is not a live parentless clique");
  for (int v = 0; v < n; ++v) {
    const bool eliminated = !fixed[v] && !awaiting(v);
    if (fixed[v] && frontal_count[v] != 0) fail("fixed pose " + std::to_string(v) + " is frontal");
    if (eliminated && frontal_count[v] != 1)
      fail("variable " + std::to_string(v) + " is frontal in " + std::to_string(frontal_count[v]) +
           " cliques");
  }
  // Every factor lies within the clique of its first eliminated variable: some non-fixed key's
  // clique holds every other non-fixed key.
  auto contains = [&](int c, int v) {
    const CliqueD& k = cliques[c];
    return std::find(k.frontals.begin(), k.frontals.end(), v) != k.frontals.end() ||
           std::find(k.separator.begin(), k.separator.end(), v) != k.separator.end();
  };
  for (size_t f = 0; f < factors.size(); ++f) {
    if (!attached[f]) continue;  // weight 0: not in the structure
    const Factor& e = factors[f];
    bool held = false, any = false;
    for (int k = 0; k < e.arity() && !held; ++k) {
      const int v = e.key(k);
      if (fixed[v] || awaiting(v) || clique_of[v] < 0) continue;
      any = true;
      bool all = true;
      for (int l = 0; l < e.arity(); ++l)
        all = all && (fixed[e.key(l)] || contains(clique_of[v], e.key(l)));
      held = all;
    }
    if (any && !held) {
      std::string keys;
      for (int k = 0; k < e.arity(); ++k) keys += (k ? ", " : "") + std::to_string(e.key(k));
      fail("factor " + std::to_string(f) + " (" + keys + ") lies in no clique");
    }
  }
}

template <int D>
TreeMemory BayesTree<D>::memory() const {
  TreeMemory m;
  double sep_sum = 0;
  for (const CliqueD& c : cliques) {
    m.clique_bytes_reserved += (c.storage.capacity() + c.pending.size()) * sizeof(double);
    if (!c.in_use) {
      ++m.free_cliques;
      continue;
    }
    ++m.cliques;
    m.clique_bytes += (c.storage.size() + c.pending.size()) * sizeof(double);
    m.max_frontal_dim = std::max(m.max_frontal_dim, c.F);
    m.max_separator_dim = std::max(m.max_separator_dim, c.Sn);
    sep_sum += c.Sn;
  }
  if (m.cliques > 0) m.mean_separator_dim = sep_sum / m.cliques;
  return m;
}

template class BayesTree<3>;
template class BayesTree<6>;
template void BayesTree<3>::checkInvariants(const std::vector<Factor<SE2>>&,
                                            const std::vector<char>&, const std::vector<char>&,
                                            const std::function<bool(int)>&) const;
template void BayesTree<6>::checkInvariants(const std::vector<Factor<SE3>>&,
                                            const std::vector<char>&, const std::vector<char>&,
                                            const std::function<bool(int)>&) const;

}  // namespace arbor::bayestree
