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
// root, where Σ = (RᵀR)⁻¹. all() walks the whole tree so, top-down, once.
//
// One variable's marginal, or the joint of two, needs no clique joint: with Σ = (RᵀR)⁻¹ over the
// whole tree's square root R (the cliques' [R S] rows, in elimination order),
//
//   Σ_ab = Y_aᵀ Y_b,   Y_v = R⁻ᵀ E_v   (E_v: the identity's D columns of v),              (2)
//
// and Rᵀ Y_v = E_v is a forward substitution whose solution is zero before v and off the path
// from v's clique to the root (a clique's rows couple its frontals only to themselves and,
// through S, to its separator, which is frontal higher up the path). So Y_v lives on v's path,
// and Σ_ab sums y_aᵀ y_b over the cliques the two paths share (from the lowest common ancestor to
// the root; none for two components: Σ_ab = 0). Within a clique, y is zero above the first row
// its right-hand side reaches (L lower triangular), so each clique solves only from there on.
//
// Each is the covariance of the linear system the tree holds: of the tangent τ at the
// linearisation point θ (x = θ ⊞ τ), in the gauge of the fixed poses (constants, not in the
// tree).
#pragma once

#include <cstdint>
#include <mutex>
#include <unordered_map>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "arbor_slam/bayestree/bayes_tree.h"
#include "arbor_slam/bayestree/work_lanes.h"

namespace arbor::bayestree {

/// D: the dimension of one variable. Thread-safe (the path solves' scratch is serialised on a
/// mutex); a copy, or an assignment, starts with empty scratch. Nothing is cached between
/// queries but by jointKept(), whose path solves last until forget(): the owner of the tree
/// calls forget() whenever the tree changes.
template <int D>
class TreeMarginals {
 public:
  using Block = Eigen::Matrix<double, D, D>;
  using JointBlock = Eigen::Matrix<double, 2 * D, 2 * D>;

  TreeMarginals() = default;
  TreeMarginals(const TreeMarginals&) {}
  TreeMarginals& operator=(const TreeMarginals&) {
    forget();
    return *this;
  }

  /// Σ_vv of variable v by the path solve (2); v must be frontal in some clique
  /// (tree.clique_of[v] ≥ 0). O(Σ (F² + F·Sn) D) over the cliques on v's path.
  Block marginal(const BayesTree<D>& tree, int v);
  /// [[Σ_aa, Σ_ab], [Σ_ba, Σ_bb]] by two path solves (2); a variable with clique_of < 0 (a
  /// constant) has zero rows. Twice a marginal's cost, plus O(F·D²) per shared clique.
  JointBlock joint(const BayesTree<D>& tree, int a, int b);
  /// joint() from each variable's path solve kept across calls until forget(): for many
  /// queries on one tree (a pose's path is then solved once, and a query costs the shared
  /// cliques' products alone). The caller must forget() before the tree changes.
  JointBlock jointKept(const BayesTree<D>& tree, int a, int b);
  /// For many jointKept() queries on one tree: the joint of every pair (a, b) whose two
  /// variables share a clique (both among the [frontals; separator] of a's clique or of b's:
  /// the two poses of every factor the tree holds do) is read off that clique's joint, from
  /// one walk (1) down the cliques the pairs need and their ancestors, and kept, as the path
  /// solves are, until forget(). jointKept() answers those pairs from it; other pairs (and
  /// pairs with a constant) still take path solves. About one factorisation's flops however
  /// many pairs, where a path solve per pose costs its path's cliques each. The walk keeps the
  /// marginal of every frontal of the cliques it visits too (marginalKept). Returns how many
  /// of the pairs were kept.
  ///
  /// With `lanes` (the tree owner's threads, idle meanwhile: WorkLanes is not reentrant), the
  /// walk goes down independent subtrees side by side, a clique's joint from its parent's as
  /// soon as the parent's is done; each clique's joint is the same computation either way, so
  /// the kept values are the same bit for bit.
  int keepSharedCliqueJoints(const BayesTree<D>& tree,
                             const std::vector<std::pair<int, int>>& pairs,
                             WorkLanes* lanes = nullptr);
  /// Σ_vv from what is kept until forget(): keepSharedCliqueJoints' walk (the marginal of
  /// every frontal of the cliques it visited) or jointKept's path solve of v, else v's path
  /// solve, then kept (v frontal in some clique).
  Block marginalKept(const BayesTree<D>& tree, int v);
  /// Drops the kept path solves, joints and marginals.
  void forget();
  /// (*out)[v] = Σ_vv for every variable frontal in the tree (others untouched), in one walk
  /// down the tree (1) that keeps a clique's joint only until its children have read it. out
  /// must have an entry per variable.
  static void all(const BayesTree<D>& tree, std::vector<Block>* out);
  /// A Σ Aᵀ for a linear map A = [A_1 … A_k] on variables vars[k] (A_k: m×D, `blocks[k]`),
  /// without forming Σ (see predicted() in marginals.cc): one forward substitution along the
  /// variables' paths to the root, O(Σ over those cliques of (F + Sn)·F·m). A variable with
  /// clique_of < 0 (a constant) contributes nothing.
  static Eigen::MatrixXd predicted(const BayesTree<D>& tree, const std::vector<int>& vars,
                                   const std::vector<Eigen::MatrixXd>& blocks);

 private:
  /// Y_v of (2) on v's path: path[k] the k-th clique up from v's, its rows of Y at
  /// y[offset[k]·D …] (F_k × D, column-major), zero above row first[k].
  struct PathSolve {
    std::vector<int> path, offset, first;
    std::vector<double> y;
  };
  /// v's path solve and Σ_vv from kept_, solved and kept on first use (mutex_ held).
  const std::pair<PathSolve, Block>& keptPath(const BayesTree<D>& tree, int v);
  /// Fills *out with Y_v (tree.clique_of[v] ≥ 0) and returns Y_vᵀY_v = Σ_vv.
  static Block solvePath(const BayesTree<D>& tree, int v, PathSolve* out, std::vector<double>* By);
  /// (1) for clique c, given its parent's joint (null for a root): its joint.
  static void jointOf(const BayesTree<D>& tree, int c, const Eigen::MatrixXd* parent,
                      Eigen::MatrixXd* joint, Eigen::MatrixXd* X);
  /// Depth first from the roots over the cliques `needed` marks (null: every clique; a marked
  /// clique's ancestors must be marked too): each clique's joint by (1) from its parent's,
  /// handed to visit(c, joint) and kept until its last marked child has read it, so the memory
  /// held is that of the cliques on the current path and their waiting siblings' parents.
  template <class Visit>
  static void walkJoints(const BayesTree<D>& tree, const std::vector<char>* needed, Visit&& visit);
  /// walkJoints over `lanes`: visit(c, joint) runs on any lane, once per marked clique, after
  /// its parent's; it must only write what belongs to c. A joint is freed once its last marked
  /// child has read it.
  template <class Visit>
  static void walkJointsOnLanes(const BayesTree<D>& tree, const std::vector<char>& needed,
                                WorkLanes* lanes, Visit&& visit);
  /// Position of v (block index) among clique c's frontals then separator.
  static int position(const Clique<D>& c, int v);

  /// Σ_ab from two path solves (over their common tail) into a joint with their Σ_aa, Σ_bb.
  static JointBlock combine(const BayesTree<D>& tree, const PathSolve& pa, const Block& aa,
                            const PathSolve& pb, const Block& bb);

  std::mutex mutex_;
  PathSolve pa_, pb_;       ///< the path solves of a query (a and b for a joint)
  std::vector<double> by_;  ///< B y_c, per clique of a path solve
  /// jointKept's path solves and Σ_vv, by variable, until forget().
  std::unordered_map<int, std::pair<PathSolve, Block>> kept_;
  /// keepSharedCliqueJoints' joints, by pair (a, b) as given, until forget().
  std::unordered_map<std::uint64_t, JointBlock> kept_pairs_;
  /// keepSharedCliqueJoints' Σ_vv of the frontals of the cliques it visited, until forget().
  std::unordered_map<int, Block> kept_marginals_;
  static std::uint64_t pairKey(int a, int b) {
    return (static_cast<std::uint64_t>(static_cast<std::uint32_t>(a)) << 32) |
           static_cast<std::uint32_t>(b);
  }
};

extern template class TreeMarginals<3>;
extern template class TreeMarginals<6>;

}  // namespace arbor::bayestree
