// The Bayes tree's structure (Kaess et al., IJRR 2012, §3): the cliques (bayestree/clique.h) with
// their allocation and free list, the roots, the clique where each variable is frontal; removing
// the top (IJRR 2012 Alg. 4 step 1: the marked cliques and all their ancestors, leaving the
// orphaned subtrees), re-attaching an orphan, the invariants, and the memory held.
#pragma once

#include <functional>
#include <vector>

#include "arbor_slam/bayestree/clique.h"
#include "arbor_slam/bayestree/incremental_smoother.h"

namespace arbor::bayestree {

/// D: the dimension of one variable (3 for SE(2), 6 for SE(3)).
template <int D>
class BayesTree {
 public:
  using CliqueD = Clique<D>;

  /// The removed top: its variables (the caller's new ones first, then the removed cliques'
  /// frontals in the order they were removed) and the orphans (subtrees below it, which keep
  /// their cached factors).
  struct Top {
    std::vector<int> variables;
    std::vector<int> orphans;
  };

  std::vector<CliqueD> cliques;   ///< indexed by clique id; in use or free
  std::vector<int> roots;         ///< cliques without a parent
  std::vector<int> clique_of;     ///< variable → clique where it is frontal (−1: fixed / new)
  std::vector<int> free_cliques;  ///< ids of cliques not in use, to recycle
  int num_cliques = 0;            ///< cliques in use
  /// Flops of factorising the cliques in use (Σ cliqueFlops) and the doubles their matrices
  /// need (Σ cliqueDoubles), changed by countClique only: removeTop takes the removed cliques'
  /// off, the top elimination adds the new ones', a fold-in the growth of the separators it
  /// extends.
  double flops = 0;
  double doubles = 0;
  /// Deferred cliques (Clique::unseen not empty), oldest first; may also hold ids since solved or
  /// freed (skipped: unseen empty or not in use). num_deferred counts the deferred cliques.
  std::vector<int> deferred;
  int num_deferred = 0;
  /// Which cliques keep their cached factor (the top elimination applies it); by default every
  /// one (a bare tree; the smoother sets its options).
  CachedFactorOptions cached_factors{0, 0};

  /// F³/3 + F²S + FS² for a clique of `frontals` and `separator` variables (F = D·frontals,
  /// S = D·separator): its dense Cholesky, the off-diagonal solve and the Schur complement.
  static double cliqueFlops(size_t frontals, size_t separator) {
    const double F = static_cast<double>(frontals) * D, S = static_cast<double>(separator) * D;
    return F * F * F / 3 + F * F * S + F * S * S;
  }
  /// F(F+S) + F + S² + S for such a clique: its conditional [R S], d and its cached factor on
  /// the separator (Clique::storage without the room to grow); F(F+S) + F without the cached
  /// factor.
  static double cliqueDoubles(size_t frontals, size_t separator, bool cached = true) {
    const double F = static_cast<double>(frontals) * D, S = static_cast<double>(separator) * D;
    return F * (F + S) + F + (cached ? S * S + S : 0.0);
  }
  /// Whether a clique of that shape keeps its cached factor (CachedFactorOptions): always at
  /// max_ratio 0, else when S² ≤ max_ratio·F(F+S), the cached factor no larger than max_ratio
  /// times the conditional.
  bool keepsCachedFactor(size_t frontals, size_t separator) const {
    return keepsCachedFactor(frontals, separator, cached_factors.max_ratio);
  }
  /// Whether a tree that would hold `all_kept_doubles` with every cached factor drops any
  /// (CachedFactorOptions::min_tree_doubles): asked by the top elimination of the tree it makes,
  /// and by the decay watch of the whole graph's fresh tree.
  bool dropsCachedFactors(double all_kept_doubles) const {
    return all_kept_doubles >= cached_factors.min_tree_doubles;
  }
  static bool keepsCachedFactor(size_t frontals, size_t separator, double max_ratio) {
    if (max_ratio <= 0) return true;
    const double F = static_cast<double>(frontals) * D, S = static_cast<double>(separator) * D;
    return S * S <= max_ratio * F * (F + S);
  }
  /// Adds (`sign` +1) or takes off (−1) a clique of that shape in `flops` and `doubles`: the
  /// one place the two sums change, so they move together.
  void countClique(size_t frontals, size_t separator, double sign, bool cached) {
    flops += sign * cliqueFlops(frontals, separator);
    doubles += sign * cliqueDoubles(frontals, separator, cached);
  }
  void countClique(const CliqueD& c) {
    countClique(c.frontals.size(), c.separator.size(), 1.0, c.cached);
  }

  /// slots[v] = v's position (in variables) among clique c's frontals then separator, until
  /// clearSlots.
  static void setSlots(const CliqueD& c, std::vector<int>* slots) {
    const int nf = static_cast<int>(c.frontals.size());
    for (int a = 0; a < nf; ++a) (*slots)[c.frontals[a]] = a;
    for (int b = 0; b < static_cast<int>(c.separator.size()); ++b)
      (*slots)[c.separator[b]] = nf + b;
  }
  static void clearSlots(const CliqueD& c, std::vector<int>* slots) {
    for (int v : c.frontals) (*slots)[v] = -1;
    for (int v : c.separator) (*slots)[v] = -1;
  }

  /// A new variable (not yet in any clique).
  void addVariable() { clique_of.push_back(-1); }

  /// A clique in use (a recycled one keeps its storage), with no variables and no links.
  int allocClique();
  /// Returns clique `id` to the free list (its storage kept for recycling).
  void freeClique(int id);
  /// Frees the storage of the cliques freed since the last call and not recycled (those on the
  /// free list hold none). O(cliques freed since then), not O(free list).
  void releaseFreeStorage();

  bool isAncestorOrSelf(int ancestor, int c) const;

  /// Adds v to clique `id`'s unseen variables (listing the clique as deferred if it was not).
  void addUnseen(int id, int v);
  /// Empties clique `id`'s unseen variables: it has been solved.
  void clearUnseen(int id);
  /// Empties every clique's unseen variables (a solve of every clique). O(deferred list).
  void clearAllUnseen();

  /// Adds to `marked` every clique that holds v (frontal or separator), for each v of `vars`:
  /// the subtree below v's frontal clique where v appears in the separator.
  void cliquesContaining(const std::vector<int>& vars, std::vector<int>* marked);

  /// IJRR 2012 Alg. 4 step 1, "Remove top of Bayes tree: (a) For each affected variable in J
  /// remove the corresponding clique and all parents up to the root. (b) Store orphaned
  /// sub-trees T_O of removed cliques." Removes `marked` and all their ancestors (each once),
  /// appends their frontals to top->variables and their children not removed to top->orphans
  /// (both in removal order), takes them off the roots and frees them. A child without a cached
  /// factor (Clique::cached) is removed too, not orphaned: nothing would stand for it in the
  /// re-eliminated top. The unseen variables of the removed cliques pass to the orphans that hold
  /// any of them in their separator (their solve was deferred with the removed clique's).
  void removeTop(const std::vector<int>& marked, Top* top);

  /// Hangs subtree `orphan` below clique `parent` (IJRR 2012 Alg. 4 step 6).
  void attachOrphan(int orphan, int parent);

  /// Throws std::logic_error naming the first violated invariant: every clique in use has a
  /// frontal, matrices of its variables' size, frontals that are not fixed, frontal once and
  /// pointed to by clique_of, none also in its separator; a root has an empty separator and is
  /// among the roots, a non-root a live parent that lists it, a non-empty separator inside the
  /// parent's variables (running intersection); children point back; no parent cycle; the
  /// count of cliques and their flops; every variable not fixed and not `awaiting(v)` (about to be
  /// eliminated) frontal exactly once, fixed ones never; every factor (arity(), key(k)) in the
  /// structure (`attached[f]`, LinearizedFactors::attached) held by the clique of one of its
  /// variables.
  template <class Factor>
  void checkInvariants(const std::vector<Factor>& factors, const std::vector<char>& attached,
                       const std::vector<char>& fixed,
                       const std::function<bool(int)>& awaiting) const;

  /// The cliques' share of TreeMemory (all but scratch_bytes).
  TreeMemory memory() const;

 private:
  int remove_stamp_ = 0;
  std::vector<int> removed_, stack_, unseen_;
  std::vector<int> freed_since_release_;  // may hold ids recycled since (skipped: in use)
};

}  // namespace arbor::bayestree
