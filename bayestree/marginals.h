// Marginal covariances from the Bayes tree (Kaess & Dellaert, "Covariance recovery from a square
// root information matrix for data association", RAS 57(12), 2009; on the Bayes tree as GTSAM's
// Marginals and ISAM2::marginalCovariance): the covariance of one variable and the joint
// covariance of two, from the cliques' conditionals, without forming or inverting the whole
// information matrix.
//
// A clique c holds the Gaussian conditional R x_f + S x_s = d + ν, ν ~ N(0, I), on its frontals
// x_f given its separator x_s (bayestree/clique.h). With X = R⁻¹S,
//
//   x_f = R⁻¹(d − ν) − X x_s,   so   Σ_fs = −X Σ_ss,   Σ_ff = (RᵀR)⁻¹ + X Σ_ss Xᵀ,      (1)
//
// and Σ_ss lies inside the joint covariance of the parent's variables (running intersection):
// the joint of a clique's [frontals; separator] follows from its parent's, top-down from the
// root, where Σ = (RᵀR)⁻¹. A joint query computes the joints on the path from its clique to the
// root only, and keeps them (with X) until the tree changes: the paper's dynamic programming over
// the entries of Σ that are needed, per clique instead of per entry, so a second query on the same
// path, or one below a clique already computed, costs only its own cliques.
//
// Two variables a, b in cliques c_a ≠ c_b: with l their lowest common ancestor, a and b are
// conditionally independent given the variables of l, and (1) read along the path from c_a up to
// l's child gives x_a = T_a x_{V_a} + (noise of those cliques) with V_a ⊂ vars(l) (GTSAM's
// "shortcut"); so Σ_ab = T_a Σ_l[V_a, V_b] T_bᵀ, with T_a = I and V_a = {a} when c_a = l. Cliques
// in different trees (components) are independent: Σ_ab = 0.
//
// One variable's marginal alone needs no joint: with Σ = (RᵀR)⁻¹ over the whole tree's square
// root R (the cliques' [R S] rows, in elimination order),
//
//   Σ_vv = YᵀY,   Y = R⁻ᵀ E_v   (E_v: the identity's D columns of v),                  (2)
//
// and Rᵀ Y = E_v is a forward substitution whose solution is zero before v and off the path
// from v's clique to the root (a clique's rows couple its frontals only to themselves and,
// through S, to its separator, which is frontal higher up the path). marginal() solves it along
// the path unless the clique's joint is cached already.
//
// Each is the covariance of the linear system the tree holds: of the tangent τ at the
// linearisation point θ (x = θ ⊞ τ), in the gauge of the fixed poses (constants, not in the
// tree).
#pragma once

#include <mutex>
#include <vector>

#include <Eigen/Core>

#include "arbor/bayestree/bayes_tree.h"

namespace arbor::bayestree {

/// D: the dimension of one variable. The cache of clique joints is valid for one version of the
/// tree (a number the owner changes whenever the tree changes); every query names the version,
/// and a new one clears the cache. Thread-safe (queries are serialised on a mutex); a copy
/// starts with an empty cache.
template <int D>
class TreeMarginals {
 public:
  using Block = Eigen::Matrix<double, D, D>;
  using JointBlock = Eigen::Matrix<double, 2 * D, 2 * D>;

  TreeMarginals() = default;
  TreeMarginals(const TreeMarginals&) {}
  TreeMarginals& operator=(const TreeMarginals&) {
    std::lock_guard<std::mutex> lock(mutex_);
    clear();
    return *this;
  }

  /// Σ_vv of variable v; v must be frontal in some clique (tree.clique_of[v] ≥ 0). From the
  /// cached joint of its clique when there is one, else by the path solve (2) (caching nothing).
  Block marginal(const BayesTree<D>& tree, long version, int v);
  /// [[Σ_aa, Σ_ab], [Σ_ba, Σ_bb]]; a variable with clique_of < 0 (a constant) has zero rows.
  JointBlock joint(const BayesTree<D>& tree, long version, int a, int b);
  /// (*out)[v] = Σ_vv for every variable frontal in the tree (others untouched), in one walk
  /// down the tree that keeps a clique's joint only until its children have read it (the
  /// cache is neither used nor changed). out must have an entry per variable.
  static void all(const BayesTree<D>& tree, std::vector<Block>* out);
  /// A Σ Aᵀ for a linear map A = [A_1 … A_k] on variables vars[k] (A_k: m×D, `blocks[k]`),
  /// without forming Σ (see predicted() in marginals.cc): one forward substitution along the
  /// variables' paths to the root, O(Σ over those cliques of (F + Sn)·F·m). A variable with
  /// clique_of < 0 (a constant) contributes nothing. The cache is neither used nor changed.
  static Eigen::MatrixXd predicted(const BayesTree<D>& tree, const std::vector<int>& vars,
                                   const std::vector<Eigen::MatrixXd>& blocks);
  /// Cliques whose joint is cached now.
  int cachedCliques() const;

 private:
  struct Entry {
    Eigen::MatrixXd joint;  ///< Σ over [frontals; separator] (empty: not computed)
    Eigen::MatrixXd X;      ///< R⁻¹S (F×Sn)
  };
  void sync(const BayesTree<D>& tree, long version);
  void clear();
  /// Computes (and caches) the joints on the path from clique c to the root; returns c's.
  const Eigen::MatrixXd& cliqueJoint(const BayesTree<D>& tree, int c);
  /// (1) for clique c, given its parent's joint (null for a root): its joint and X.
  static void jointOf(const BayesTree<D>& tree, int c, const Eigen::MatrixXd* parent,
                      Eigen::MatrixXd* joint, Eigen::MatrixXd* X);
  /// x_v = T x_{V} + noise, V ⊂ variables of clique l, from v's clique c (a descendant of l).
  void shortcut(const BayesTree<D>& tree, int v, int c, int l, std::vector<int>* V,
                Eigen::MatrixXd* T);
  /// (2) for variable v along the path from its clique to the root.
  Block pathMarginal(const BayesTree<D>& tree, int v);
  /// Position of v (block index) among clique c's frontals then separator.
  static int position(const Clique<D>& c, int v);

  mutable std::mutex mutex_;
  long version_ = -1;
  std::vector<Entry> cache_;  ///< per clique id
  std::vector<int> cached_;   ///< clique ids with an entry
  std::vector<int> path_;
  std::vector<int> mark_;  ///< per clique, for the lowest common ancestor
  // pathMarginal's scratch: per path clique its first row, per variable its row (−1: not a
  // frontal of the path), the rows r_c / y_c and B y_c.
  std::vector<int> offset_;
  std::vector<int> row_of_;
  std::vector<double> buffer_;
  int mark_stamp_ = 0;
};

extern template class TreeMarginals<3>;
extern template class TreeMarginals<6>;

}  // namespace arbor::bayestree
