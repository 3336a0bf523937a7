// A clique of the Bayes tree (Kaess et al., IJRR 2012, §3): its frontal and separator variables,
// the conditional ‖R x_f + S x_s − d‖² on its frontals given its separator, and the factor it
// passes to its parent (the Schur complement on the separator, "cached factor"), in one block of
// storage; and the changes a fold-in makes to them in place (docs/design.md, "Loop closures by
// rank updates"): a separator that grows, a rank-D update of the factor, the cached factor's
// pending updates; and a clique that keeps no cached factor (docs/design.md, "Cliques without a
// cached factor").
#pragma once

#include <algorithm>
#include <cstddef>
#include <vector>

#include <Eigen/Core>

#include "arbor_slam/bayestree/dense_kernels.h"

namespace arbor::bayestree {

/// D: the dimension of one variable (3 for SE(2), 6 for SE(3)).
template <int D>
struct Clique {
  using Map = Eigen::Map<Eigen::MatrixXd, 0, Eigen::OuterStride<>>;
  using ConstMap = Eigen::Map<const Eigen::MatrixXd, 0, Eigen::OuterStride<>>;
  using ConstVecMap = Eigen::Map<const Eigen::VectorXd>;

  /// Separators up to this order take a fold-in's update of their cached factor at once.
  static constexpr int kDirectUpdateOrder = 48;
  /// At most this much of a recycled buffer's spare capacity becomes separator room (4 poses).
  static constexpr int kAllocationRoom = 4 * D;
  /// A separator of at least this order gets room for an eighth more at elimination.
  static constexpr int kRoomySeparator = 64 * D;

  std::vector<int> frontals;   ///< in elimination order
  std::vector<int> separator;  ///< poses of the parent's frontals ∪ separator
  int parent = -1;
  std::vector<int> children;
  /// One allocation: [LS (ld×F) | d (F) | cached H (ldh×ldh) | cached g (ldh)], column-major,
  /// F = nf·D, Sn = ns·D, N = F + Sn ≤ ld, Sn ≤ ldh (room for the separator to grow in place);
  /// LS = [L; Sᵀ] (rows 0..N−1) with R = Lᵀ (so R x_f + S x_s = d). The cached H holds its
  /// lower triangle and full diagonal D×D blocks.
  DoubleBuffer storage;
  /// Rank updates of the cached factor not yet applied: it is [H g] + P_s [P_sᵀ P_gᵀ], with
  /// P = [P_s; P_g] ((Sn+1)×K, the first pending_cols columns). Applied when the parent reads
  /// the cached factor, or when K reaches a quarter of Sn.
  Eigen::MatrixXd pending;
  int pending_cols = 0;
  int F = 0, Sn = 0, ld = 0, ldh = 0;
  int eliminated_sn = 0;  ///< Sn when last eliminated (the separator grows by fold-ins)
  bool dirty = false;     ///< changed since the last back-substitution
  /// Separator variables that moved by at least the wildfire threshold since this clique was
  /// last solved, which a solve budget (PartialSolve) left for a later update; not empty ⇔ the
  /// clique is deferred (BayesTree::deferred lists it). Its solve passes them on to the cliques
  /// below that hold them.
  std::vector<int> unseen;
  bool damped = false;  ///< the factor is of a damped (indeterminate) Hessian
  bool in_use = false;
  /// Keeps its cached factor (BayesTree::keepsCachedFactor when eliminated). Without one
  /// (ldh = 0 once its parent has read it) the clique cannot be an orphan: BayesTree::removeTop
  /// removes it with its parent, and the top elimination re-eliminates it from its factors and
  /// its children's cached factors.
  bool cached = true;
  int removed_stamp = -1;
  /// Entries of [L; Sᵀ] in the subtree it roots (itself included) when last eliminated: what
  /// back-substituting the subtree reads.
  double subtree_entries = 0;
  int path_stamp = -1;

  static size_t sizeFor(int F, int ld, int ldh) {
    return static_cast<size_t>(ld) * F + F + static_cast<size_t>(ldh) * ldh + ldh;
  }
  /// Sizes the storage for the current frontals and separator (before elimination). A recycled
  /// buffer larger than needed keeps its size (DoubleBuffer::fit), and what it has beyond the
  /// need, up to four poses, becomes room for fold-ins to grow the separator in place: the
  /// first extension after an elimination then copies nothing.
  void allocate() {
    F = static_cast<int>(frontals.size()) * D;
    Sn = static_cast<int>(separator.size()) * D;
    eliminated_sn = Sn;
    storage.fit(sizeFor(F, F + Sn, Sn));
    int room = 0;
    while (room < kAllocationRoom &&
           sizeFor(F, F + Sn + room + D, Sn + room + D) <= storage.capacity())
      room += D;
    // Every fold-in extends each separator on its path by one pose, so after an elimination the
    // large cliques of a path would all outgrow their storage in the same update, each copied
    // and its new pages faulted in (0.4-1 GB in one update of a 50,000-pose world): room for an
    // eighth more spreads those copies out. About 27% more for those cached factors.
    if (Sn >= kRoomySeparator) room = std::max(room, D * ((Sn / 8 + D - 1) / D));
    ld = F + Sn + room;
    ldh = Sn + room;
    storage.fit(sizeFor(F, ld, ldh));
    pending.resize(0, 0);
    pending_cols = 0;
  }
  double* lsPtr() { return storage.data(); }
  double* dPtr() { return storage.data() + static_cast<size_t>(ld) * F; }
  double* hPtr() { return dPtr() + F; }
  double* gPtr() { return hPtr() + static_cast<size_t>(ldh) * ldh; }
  const double* lsPtr() const { return storage.data(); }
  const double* dPtr() const { return storage.data() + static_cast<size_t>(ld) * F; }
  const double* hPtr() const { return dPtr() + F; }
  const double* gPtr() const { return hPtr() + static_cast<size_t>(ldh) * ldh; }
  ConstMap LS() const { return ConstMap(lsPtr(), F + Sn, F, Eigen::OuterStride<>(ld)); }
  Eigen::MatrixXd R() const {  // upper triangular
    Eigen::MatrixXd L = LS().topRows(F).template triangularView<Eigen::Lower>();
    return L.transpose();
  }
  Eigen::MatrixXd S() const { return LS().bottomRows(Sn).transpose(); }
  ConstVecMap d() const { return ConstVecMap(dPtr(), F); }
  /// Valid while the storage holds it: a cached clique, or one without a cached factor until its
  /// parent's elimination has read it (dropCachedFactor).
  ConstMap cachedH() const { return ConstMap(hPtr(), Sn, Sn, Eigen::OuterStride<>(ldh)); }
  ConstVecMap cachedG() const { return ConstVecMap(gPtr(), Sn); }

  /// How far fold-ins may grow the separator: twice its size at elimination plus four poses.
  /// Without a bound, cubicle's cached factors grew to 1.1 GB (GTSAM: 0.4); with it, replay
  /// times on the 3D sets were unchanged or better (docs/benchmarks.md).
  int separatorBudget() const { return 2 * eliminated_sn + 4 * D; }

  /// Adds v to the separator. Its rows of [L; Sᵀ] and of the cached factor are zero: before the
  /// factor that needs it is folded in, v is not coupled to the frontals. The storage keeps room
  /// to grow (a quarter more), so most extensions copy nothing; `scratch` takes the old storage
  /// when it must move.
  void extendSeparator(int v, DoubleBuffer* scratch) {
    const int N = F + Sn;
    if (ld < N + D || (cached && ldh < Sn + D)) {
      const int room = D * std::max(2, Sn / (4 * D));
      const int new_ld = N + D + room, new_ldh = cached ? Sn + D + room : 0;
      scratch->fit(sizeFor(F, new_ld, new_ldh));
      double* ls = scratch->data();
      for (int k = 0; k < F; ++k)
        std::copy(lsPtr() + static_cast<size_t>(k) * ld, lsPtr() + static_cast<size_t>(k) * ld + N,
                  ls + static_cast<size_t>(k) * new_ld);
      double* d = ls + static_cast<size_t>(new_ld) * F;
      std::copy(dPtr(), dPtr() + F, d);
      double* h = d + F;
      if (cached) {
        for (int q = 0; q < Sn; ++q)
          std::copy(hPtr() + static_cast<size_t>(q) * ldh,
                    hPtr() + static_cast<size_t>(q) * ldh + Sn,
                    h + static_cast<size_t>(q) * new_ldh);
        std::copy(gPtr(), gPtr() + Sn, h + static_cast<size_t>(new_ldh) * new_ldh);
      }
      storage.swap(*scratch);
      ld = new_ld;
      ldh = new_ldh;
    }
    for (int k = 0; k < F; ++k) {
      double* col = lsPtr() + static_cast<size_t>(k) * ld;
      std::fill(col + N, col + N + D, 0.0);
    }
    if (!cached) {
      separator.push_back(v);
      Sn += D;
      return;
    }
    for (int q = 0; q < Sn + D; ++q) {
      double* col = hPtr() + static_cast<size_t>(q) * ldh;
      std::fill(col + (q < Sn ? Sn : 0), col + Sn + D, 0.0);
    }
    std::fill(gPtr() + Sn, gPtr() + Sn + D, 0.0);
    if (pending_cols > 0) {  // zero rows for v, before the right-hand side's row
      const int K = pending_cols;
      Eigen::MatrixXd grown = Eigen::MatrixXd::Zero(Sn + D + 1, pending.cols());
      grown.topLeftCorner(Sn, K) = pending.topLeftCorner(Sn, K);
      grown.row(Sn + D).head(K) = pending.row(Sn).head(K);
      pending.swap(grown);
    }
    separator.push_back(v);
    Sn += D;
  }

  /// Folds W ((F+Sn+1)×D, leading dimension ldw; rows: frontals, separator, right-hand side)
  /// into the factor by a rank-D update. On return rows F..F+Sn of W hold V, the update of the
  /// factor passed to the parent; the cached factor gets VVᵀ (at once for small separators,
  /// else pending).
  void rankUpdate(double* W, int ldw) {
    partialCholeskyUpdate(lsPtr(), ld, F + Sn, F, dPtr(), W, ldw, D);
    dirty = true;
    // A root (what is left is the constant term), or no cached factor to update.
    if (Sn == 0 || !cached) return;
    const Eigen::Map<const Eigen::MatrixXd, 0, Eigen::OuterStride<>> V(W + F, Sn + 1, D,
                                                                       Eigen::OuterStride<>(ldw));
    const int K = pending_cols;
    if (K == 0 && Sn <= kDirectUpdateOrder) {
      addOuterProduct(V);
      return;
    }
    if (pending.cols() < K + D) {  // room up to where it is applied
      Eigen::MatrixXd grown(Sn + 1, std::max(K + D, Sn / 4 + D));
      grown.leftCols(K) = pending.leftCols(K);
      pending.swap(grown);
    }
    pending.middleCols(K, D) = V;
    pending_cols = K + D;
    if (4 * pending_cols > Sn) applyPending();
  }

  /// Frees the cached factor of a clique that keeps none, once its parent's elimination has read
  /// it: the storage shrinks to [LS | d] (copied), ldh = 0.
  void dropCachedFactor() {
    if (cached || ldh == 0) return;
    const size_t keep = sizeFor(F, ld, 0);
    DoubleBuffer kept;
    kept.fit(keep);
    std::copy(storage.data(), storage.data() + keep, kept.data());
    storage.swap(kept);
    ldh = 0;
    pending.resize(0, 0);
    pending_cols = 0;
  }

  /// Applies the pending rank updates to the cached factor.
  void applyPending() {
    if (pending_cols == 0) return;
    const auto P = pending.leftCols(pending_cols);
    lowerRankUpdate(hPtr(), ldh, Sn, pending.data(), static_cast<int>(pending.rows()),
                    pending_cols);
    Eigen::Map<Eigen::VectorXd>(gPtr(), Sn).noalias() += P.topRows(Sn) * P.row(Sn).transpose();
    Map H(hPtr(), Sn, Sn, Eigen::OuterStride<>(ldh));
    for (int b = 0; b < Sn; b += D)
      H.template block<D, D>(b, b).template triangularView<Eigen::StrictlyUpper>() =
          H.template block<D, D>(b, b).transpose();
    pending.resize(0, 0);
    pending_cols = 0;
  }

 private:
  /// [H g] += V_s [V_sᵀ V_gᵀ] (lower triangle and full diagonal blocks), V = [V_s; V_g] with D
  /// columns: D contiguous axpys per column, faster than a general product at small orders.
  template <class Block>
  void addOuterProduct(const Block& V) {
    double* h = hPtr();
    double* g = gPtr();
    for (int q = 0; q < Sn; ++q) {
      double* col = h + static_cast<size_t>(q) * ldh;
      const int first = q - q % D;
      for (int t = 0; t < D; ++t) {
        const double vqt = V(q, t);
        const double* vt = V.data() + static_cast<size_t>(t) * V.outerStride();
        for (int p = first; p < Sn; ++p) col[p] += vqt * vt[p];
      }
      g[q] += V.row(q).dot(V.row(Sn));
    }
  }
};

}  // namespace arbor::bayestree
