#include "arbor_slam/bayestree/marginals.h"

#include <algorithm>
#include <atomic>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <utility>

#include <Eigen/Core>

#include "arbor_slam/bayestree/dense_kernels.h"

namespace arbor::bayestree {

// keepSharedCliqueJoints' walk shares its cliques among the lanes from this many cliques on
// (a clique's joint is tens of µs on smallGrid3D, a helper's wake-up tens of µs too).
constexpr int kMinSharedWalk = 16;

template <int D>
int TreeMarginals<D>::position(const Clique<D>& c, int v) {
  const auto f = std::find(c.frontals.begin(), c.frontals.end(), v);
  if (f != c.frontals.end()) return static_cast<int>(f - c.frontals.begin());
  const auto s = std::find(c.separator.begin(), c.separator.end(), v);
  if (s != c.separator.end())
    return static_cast<int>(c.frontals.size() + (s - c.separator.begin()));
  throw std::logic_error("TreeMarginals: variable " + std::to_string(v) + " not in its clique");
}

// (1) for clique c: X = R⁻¹S = L⁻ᵀBᵀ with [L; B] = [Rᵀ; Sᵀ] as stored, (RᵀR)⁻¹ = L⁻ᵀL⁻¹
// (dpotri on L, 2F³/3 flops), Σ_ss gathered from the parent's joint, Σ_fs = −X Σ_ss,
// Σ_ff = (RᵀR)⁻¹ − Σ_fs Xᵀ (symmetric: its lower triangle only, then mirrored).
template <int D>
void TreeMarginals<D>::jointOf(const BayesTree<D>& tree, int c, const Eigen::MatrixXd* parent,
                               Eigen::MatrixXd* joint, Eigen::MatrixXd* X) {
  const Clique<D>& k = tree.cliques[c];
  const int F = k.F, Sn = k.Sn;
  const auto L = k.LS().topRows(F).template triangularView<Eigen::Lower>();
  joint->resize(F + Sn, F + Sn);
  auto Sff = joint->topLeftCorner(F, F);
  Sff.template triangularView<Eigen::Lower>() = k.LS().topRows(F);
  // A zero pivot (a singular conditional): NaN, which the covariances and the innovations read
  // from them pass on as not finite.
  if (!inverseFromCholesky(joint->data(), F + Sn, F))
    Sff.setConstant(std::numeric_limits<double>::quiet_NaN());
  if (Sn > 0) {
    *X = k.LS().bottomRows(Sn).transpose();
    L.transpose().solveInPlace(*X);
    const Clique<D>& p = tree.cliques[k.parent];
    const int ns = static_cast<int>(k.separator.size());
    std::vector<int> at(ns);
    for (int b = 0; b < ns; ++b) at[b] = position(p, k.separator[b]) * D;
    auto Sss = joint->bottomRightCorner(Sn, Sn);
    for (int b = 0; b < ns; ++b)
      for (int q = 0; q < ns; ++q)
        Sss.template block<D, D>(b * D, q * D) = parent->template block<D, D>(at[b], at[q]);
    auto Sfs = joint->topRightCorner(F, Sn);
    Sfs.noalias() = -*X * Sss;
    Sff.template triangularView<Eigen::Lower>() -= Sfs * X->transpose();
    joint->bottomLeftCorner(Sn, F) = Sfs.transpose();
  }
  for (int j = 1; j < F; ++j)  // the upper triangle from the lower
    for (int i = 0; i < j; ++i) Sff(i, j) = Sff(j, i);
}

// (2): Y_v = R⁻ᵀE_v by forward substitution along the path from v's clique to the root. Per
// clique c, bottom-up, with [L; B] = [Rᵀ; Sᵀ] as stored and r_c the right-hand side so far (zero
// above row f): y_c = L⁻¹ r_c, which is zero above f too, so only L[f:, f:] is read; then
// r_s −= B y_c for the separator's rows (frontal rows of cliques above on the path), reading
// B[:, f:] only; Σ_vv = Σ_c y_cᵀ y_c.
template <int D>
typename TreeMarginals<D>::Block TreeMarginals<D>::solvePath(const BayesTree<D>& tree, int v,
                                                             PathSolve* out,
                                                             std::vector<double>* by) {
  using Rows = Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, D>>;
  std::vector<int>& path = out->path;
  std::vector<int>& offset = out->offset;
  std::vector<int>& first = out->first;
  path.clear();
  offset.clear();
  first.clear();
  int rows = 0, max_sn = 0;
  for (int p = tree.clique_of[v]; p >= 0; p = tree.cliques[p].parent) {
    const Clique<D>& q = tree.cliques[p];
    path.push_back(p);
    offset.push_back(rows);
    first.push_back(q.F);  // nothing reached yet
    rows += q.F;
    max_sn = std::max(max_sn, q.Sn);
  }
  out->y.assign(static_cast<size_t>(rows) * D, 0.0);
  by->resize(static_cast<size_t>(max_sn) * D);
  auto rowsOf = [&](size_t k) {  // y_c of the k-th clique of the path, F×D
    return Rows(out->y.data() + static_cast<size_t>(offset[k]) * D, tree.cliques[path[k]].F, D);
  };
  const int at = position(tree.cliques[path[0]], v) * D;
  rowsOf(0).template middleRows<D>(at).setIdentity();
  first[0] = at;
  Block sigma = Block::Zero();
  for (size_t k = 0; k < path.size(); ++k) {
    const Clique<D>& q = tree.cliques[path[k]];
    const int f = first[k], n = q.F - f;
    if (n <= 0) continue;  // nothing reached this clique: y_c = 0
    const auto LS = q.LS();
    auto y = rowsOf(k).bottomRows(n);
    LS.block(f, f, n, n).template triangularView<Eigen::Lower>().solveInPlace(y);
    sigma.noalias() += y.transpose() * y;
    if (q.Sn == 0) continue;
    Rows By(by->data(), q.Sn, D);
    By.noalias() = LS.block(q.F, f, q.Sn, n) * y;
    size_t j = k + 1;  // the separator's cliques lie above on the path, roughly in order
    for (size_t b = 0; b < q.separator.size(); ++b) {
      const int s = q.separator[b], cs = tree.clique_of[s];
      if (j >= path.size() || path[j] != cs) {
        j = k + 1;
        while (j < path.size() && path[j] != cs) ++j;
        if (j == path.size())
          throw std::logic_error("TreeMarginals: separator variable " + std::to_string(s) +
                                 " of variable " + std::to_string(v) +
                                 "'s path is not frontal on it");
      }
      const int row = position(tree.cliques[cs], s) * D;
      rowsOf(j).template middleRows<D>(row) -= By.template middleRows<D>(static_cast<int>(b) * D);
      first[j] = std::min(first[j], row);
    }
  }
  return sigma;
}

template <int D>
typename TreeMarginals<D>::Block TreeMarginals<D>::marginal(const BayesTree<D>& tree, int v) {
  std::lock_guard<std::mutex> lock(mutex_);
  return solvePath(tree, v, &pa_, &by_);
}

// Σ_ab = Y_aᵀY_b over the cliques both paths hold: their common tail, from the lowest common
// ancestor to the root (none when a and b are in different trees), each from the later of the
// two first rows.
template <int D>
typename TreeMarginals<D>::JointBlock TreeMarginals<D>::combine(const BayesTree<D>& tree,
                                                                const PathSolve& pa,
                                                                const Block& aa,
                                                                const PathSolve& pb,
                                                                const Block& bb) {
  using Rows = Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, D>>;
  JointBlock out = JointBlock::Zero();
  out.template topLeftCorner<D, D>() = aa;
  out.template bottomRightCorner<D, D>() = bb;
  Block ab = Block::Zero();
  for (int i = static_cast<int>(pa.path.size()) - 1, j = static_cast<int>(pb.path.size()) - 1;
       i >= 0 && j >= 0 && pa.path[i] == pb.path[j]; --i, --j) {
    const int F = tree.cliques[pa.path[i]].F, f = std::max(pa.first[i], pb.first[j]);
    if (f >= F) continue;
    const Rows ya(pa.y.data() + static_cast<size_t>(pa.offset[i]) * D, F, D);
    const Rows yb(pb.y.data() + static_cast<size_t>(pb.offset[j]) * D, F, D);
    ab.noalias() += ya.bottomRows(F - f).transpose() * yb.bottomRows(F - f);
  }
  out.template topRightCorner<D, D>() = ab;
  out.template bottomLeftCorner<D, D>() = ab.transpose();
  return out;
}

template <int D>
typename TreeMarginals<D>::JointBlock TreeMarginals<D>::joint(const BayesTree<D>& tree, int a,
                                                              int b) {
  std::lock_guard<std::mutex> lock(mutex_);
  const int ca = tree.clique_of[a], cb = tree.clique_of[b];
  if (ca >= 0 && cb >= 0) {
    const Block aa = solvePath(tree, a, &pa_, &by_), bb = solvePath(tree, b, &pb_, &by_);
    return combine(tree, pa_, aa, pb_, bb);
  }
  JointBlock out = JointBlock::Zero();  // a constant: zero rows, no correlation
  if (ca >= 0) out.template topLeftCorner<D, D>() = solvePath(tree, a, &pa_, &by_);
  if (cb >= 0) out.template bottomRightCorner<D, D>() = solvePath(tree, b, &pb_, &by_);
  return out;
}

template <int D>
typename TreeMarginals<D>::JointBlock TreeMarginals<D>::jointKept(const BayesTree<D>& tree, int a,
                                                                  int b) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (!kept_pairs_.empty()) {
    if (const auto it = kept_pairs_.find(pairKey(a, b)); it != kept_pairs_.end()) return it->second;
    if (const auto it = kept_pairs_.find(pairKey(b, a)); it != kept_pairs_.end()) {
      JointBlock out;  // the same joint, its two variables swapped
      out << it->second.template bottomRightCorner<D, D>(),
          it->second.template bottomLeftCorner<D, D>(), it->second.template topRightCorner<D, D>(),
          it->second.template topLeftCorner<D, D>();
      return out;
    }
  }
  const int ca = tree.clique_of[a], cb = tree.clique_of[b];
  if (ca >= 0 && cb >= 0) {
    const auto& [pa, aa] = keptPath(tree, a);
    const auto& [pb, bb] = keptPath(tree, b);
    return combine(tree, pa, aa, pb, bb);
  }
  JointBlock out = JointBlock::Zero();  // a constant: zero rows, no correlation
  if (ca >= 0) out.template topLeftCorner<D, D>() = keptPath(tree, a).second;
  if (cb >= 0) out.template bottomRightCorner<D, D>() = keptPath(tree, b).second;
  return out;
}

template <int D>
void TreeMarginals<D>::forget() {
  std::lock_guard<std::mutex> lock(mutex_);
  kept_.clear();
  kept_pairs_.clear();
  kept_marginals_.clear();
}

template <int D>
typename TreeMarginals<D>::Block TreeMarginals<D>::marginalKept(const BayesTree<D>& tree, int v) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (const auto it = kept_marginals_.find(v); it != kept_marginals_.end()) return it->second;
  return keptPath(tree, v).second;
}

template <int D>
const std::pair<typename TreeMarginals<D>::PathSolve, typename TreeMarginals<D>::Block>&
TreeMarginals<D>::keptPath(const BayesTree<D>& tree, int v) {
  auto [it, fresh] = kept_.try_emplace(v);
  if (fresh) it->second.second = solvePath(tree, v, &it->second.first, &by_);
  return it->second;
}

template <int D>
template <class Visit>
void TreeMarginals<D>::walkJoints(const BayesTree<D>& tree, const std::vector<char>* needed,
                                  Visit&& visit) {
  const int nc = static_cast<int>(tree.cliques.size());
  auto marked = [&](int c) { return needed == nullptr || (*needed)[c]; };
  std::vector<Eigen::MatrixXd> joint(nc);
  std::vector<int> waiting(nc, 0);
  std::vector<int> stack;
  for (int r : tree.roots)
    if (marked(r)) stack.push_back(r);
  Eigen::MatrixXd X;
  auto release = [&](int c) {  // c and every ancestor whose marked children are all done
    while (c >= 0 && waiting[c] == 0) {
      joint[c].resize(0, 0);
      c = tree.cliques[c].parent;
      if (c >= 0) --waiting[c];
    }
  };
  while (!stack.empty()) {
    const int c = stack.back();
    stack.pop_back();
    const Clique<D>& k = tree.cliques[c];
    jointOf(tree, c, k.parent >= 0 ? &joint[k.parent] : nullptr, &joint[c], &X);
    visit(c, joint[c]);
    for (int ch : k.children)
      if (marked(ch)) {
        stack.push_back(ch);
        ++waiting[c];
      }
    release(c);
  }
}

template <int D>
template <class Visit>
void TreeMarginals<D>::walkJointsOnLanes(const BayesTree<D>& tree, const std::vector<char>& needed,
                                         WorkLanes* lanes, Visit&& visit) {
  const int nc = static_cast<int>(tree.cliques.size());
  std::vector<Eigen::MatrixXd> joint(static_cast<size_t>(nc));
  // Per clique: its marked children that have not read its joint yet.
  std::unique_ptr<std::atomic<int>[]> waiting(new std::atomic<int>[static_cast<size_t>(nc)]);
  std::vector<int> roots;
  int marked = 0;
  for (int c = 0; c < nc; ++c) {
    waiting[c].store(0, std::memory_order_relaxed);
    if (!needed[c]) continue;
    ++marked;
    const int p = tree.cliques[c].parent;
    if (p < 0) roots.push_back(c);
  }
  for (int c = 0; c < nc; ++c)
    if (needed[c] && tree.cliques[c].parent >= 0)
      waiting[tree.cliques[c].parent].fetch_add(1, std::memory_order_relaxed);
  std::vector<Eigen::MatrixXd> X(static_cast<size_t>(lanes->lanes()));
  lanes->run(
      roots,
      [&](int lane, int c) {
        const Clique<D>& k = tree.cliques[c];
        jointOf(tree, c, k.parent >= 0 ? &joint[k.parent] : nullptr, &joint[c], &X[lane]);
        if (k.parent >= 0 && waiting[k.parent].fetch_sub(1, std::memory_order_acq_rel) == 1)
          joint[k.parent].resize(0, 0);  // its last marked child has read it
        visit(c, joint[c]);
        int next = -1;  // the first marked child on this lane, the others to any lane
        for (int ch : k.children) {
          if (!needed[ch]) continue;
          if (next < 0) {
            next = ch;
          } else {
            lanes->push(ch);
          }
        }
        if (next < 0) joint[c].resize(0, 0);  // no marked child reads it
        return next;
      },
      /*share=*/marked >= kMinSharedWalk);
}

// The walk of all(), restricted to the cliques the pairs are read at and their ancestors: each
// pair at the clique of whichever of its variables holds the other among its [frontals;
// separator] (a factor's two variables: the one eliminated first, whose clique's separator
// or frontals hold the other).
template <int D>
int TreeMarginals<D>::keepSharedCliqueJoints(const BayesTree<D>& tree,
                                             const std::vector<std::pair<int, int>>& pairs,
                                             WorkLanes* lanes) {
  std::lock_guard<std::mutex> lock(mutex_);
  const int nc = static_cast<int>(tree.cliques.size());
  const int nv = static_cast<int>(tree.clique_of.size());
  auto holds = [&](int c, int v) {
    const Clique<D>& k = tree.cliques[c];
    return std::find(k.frontals.begin(), k.frontals.end(), v) != k.frontals.end() ||
           std::find(k.separator.begin(), k.separator.end(), v) != k.separator.end();
  };
  // Per clique, the pairs read off its joint and, after the walk, their joints (written by the
  // lane that visits the clique).
  struct ReadAt {
    std::vector<std::pair<int, int>> pairs;
    std::vector<JointBlock> joints;
  };
  std::unordered_map<int, ReadAt> at;
  std::unordered_set<std::uint64_t> seen;
  for (const auto& [a, b] : pairs) {
    if (a < 0 || b < 0 || a >= nv || b >= nv || a == b) continue;
    const int ca = tree.clique_of[a], cb = tree.clique_of[b];
    if (ca < 0 || cb < 0 || kept_pairs_.count(pairKey(a, b)) || !seen.insert(pairKey(a, b)).second)
      continue;
    if (holds(ca, b)) {
      at[ca].pairs.emplace_back(a, b);
    } else if (holds(cb, a)) {
      at[cb].pairs.emplace_back(a, b);
    }
  }
  if (at.empty()) return 0;
  // The cliques needed: those the pairs are read at and their ancestors.
  std::vector<char> needed(nc, 0);
  for (const auto& entry : at)
    for (int c = entry.first; c >= 0 && !needed[c]; c = tree.cliques[c].parent) needed[c] = 1;
  // What the walk reads off each clique goes to slots of that clique's own (its frontals'
  // marginals, its pairs' joints), so that the cliques may be visited on any lane; the kept
  // maps are filled from them after the walk.
  std::vector<std::vector<Block>> marginals(static_cast<size_t>(nc));  // by clique, its frontals'
  for (auto& entry : at) entry.second.joints.resize(entry.second.pairs.size());
  auto visit = [&](int c, const Eigen::MatrixXd& joint) {
    const Clique<D>& k = tree.cliques[c];
    std::vector<Block>& frontal = marginals[c];
    frontal.resize(k.frontals.size());
    for (size_t f = 0; f < k.frontals.size(); ++f) {
      const int at_f = static_cast<int>(f) * D;
      frontal[f] = joint.template block<D, D>(at_f, at_f);
    }
    const auto it = at.find(c);
    if (it == at.end()) return;
    ReadAt& read = it->second;
    for (size_t q = 0; q < read.pairs.size(); ++q) {
      const auto& [a, b] = read.pairs[q];
      const int pa = position(k, a) * D, pb = position(k, b) * D;
      read.joints[q] << joint.template block<D, D>(pa, pa), joint.template block<D, D>(pa, pb),
          joint.template block<D, D>(pb, pa), joint.template block<D, D>(pb, pb);
    }
  };
  if (lanes != nullptr && lanes->lanes() > 1) {
    walkJointsOnLanes(tree, needed, lanes, visit);
  } else {
    walkJoints(tree, &needed, visit);
  }
  for (int c = 0; c < nc; ++c)
    for (size_t f = 0; f < marginals[c].size(); ++f)
      kept_marginals_[tree.cliques[c].frontals[f]] = marginals[c][f];
  int count = 0;
  for (const auto& entry : at) {
    const ReadAt& read = entry.second;
    for (size_t q = 0; q < read.pairs.size(); ++q) {
      kept_pairs_[pairKey(read.pairs[q].first, read.pairs[q].second)] = read.joints[q];
      ++count;
    }
  }
  return count;
}

template <int D>
void TreeMarginals<D>::all(const BayesTree<D>& tree, std::vector<Block>* out) {
  walkJoints(tree, nullptr, [&](int c, const Eigen::MatrixXd& joint) {
    const Clique<D>& k = tree.cliques[c];
    for (size_t a = 0; a < k.frontals.size(); ++a)
      (*out)[k.frontals[a]] =
          joint.template block<D, D>(static_cast<int>(a) * D, static_cast<int>(a) * D);
  });
}

// With H = RᵀR (R the tree's square-root information, block row [Lᵀ | Bᵀ] per clique, [L; B]
// as stored), Σ = R⁻¹R⁻ᵀ and so A Σ Aᵀ = YᵀY with Y = R⁻ᵀAᵀ, i.e. RᵀY = Aᵀ. Rᵀ is lower
// triangular in elimination order (children before parents); its block column of clique c is
// [L; B] on [frontals; separator], so, children first,
//
//   Y_c = L⁻¹ (Aᵀ_{f_c} − Σ_k B_k[f_c] Y_k)   (k: the cliques whose separator holds f_c),
//
// and Y is zero outside the cliques on the variables' paths to the root: a clique pushes
// −B_c Y_c onto its separator, which is frontal in its ancestors only.
template <int D>
Eigen::MatrixXd TreeMarginals<D>::predicted(const BayesTree<D>& tree, const std::vector<int>& vars,
                                            const std::vector<Eigen::MatrixXd>& blocks) {
  using Rows = Eigen::Map<Eigen::MatrixXd>;
  const int m = blocks.empty() ? 0 : static_cast<int>(blocks.front().rows());
  Eigen::MatrixXd out = Eigen::MatrixXd::Zero(m, m);
  // The cliques on the paths, each once, deepest first (a clique pushes onto its ancestors
  // only, which are shallower); each with its rows of Aᵀ − the terms pushed onto it, F×m
  // column-major at y[offset·m …], zero above row `first`.
  struct OnPath {
    int clique, depth, offset, first;
  };
  auto inTree = [&](int v) {
    return v >= 0 && v < static_cast<int>(tree.clique_of.size()) && tree.clique_of[v] >= 0;
  };
  std::vector<OnPath> on;
  std::vector<int> up;
  for (const int v : vars) {
    if (!inTree(v)) continue;
    up.clear();
    for (int c = tree.clique_of[v]; c >= 0; c = tree.cliques[c].parent) up.push_back(c);
    for (size_t q = 0; q < up.size(); ++q) {
      const bool known =
          std::any_of(on.begin(), on.end(), [&](const OnPath& o) { return o.clique == up[q]; });
      if (known) break;  // and so are its ancestors
      on.push_back({up[q], static_cast<int>(up.size() - 1 - q), 0, tree.cliques[up[q]].F});
    }
  }
  std::sort(on.begin(), on.end(), [](const OnPath& x, const OnPath& y) {
    return x.depth != y.depth ? x.depth > y.depth : x.clique < y.clique;
  });
  int rows = 0, max_sn = 0;
  for (OnPath& o : on) {
    o.offset = rows;
    rows += tree.cliques[o.clique].F;
    max_sn = std::max(max_sn, tree.cliques[o.clique].Sn);
  }
  std::vector<double> y(static_cast<size_t>(rows) * m, 0.0);
  std::vector<double> by(static_cast<size_t>(max_sn) * m);
  auto rowsOf = [&](const OnPath& o) {
    return Rows(y.data() + static_cast<size_t>(o.offset) * m, tree.cliques[o.clique].F, m);
  };
  auto find = [&](size_t from, int clique) {
    while (from < on.size() && on[from].clique != clique) ++from;
    return from;
  };
  for (size_t k = 0; k < vars.size(); ++k) {
    const int v = vars[k];
    if (!inTree(v)) continue;
    OnPath& o = on[find(0, tree.clique_of[v])];
    const int row = position(tree.cliques[o.clique], v) * D;
    rowsOf(o).middleRows(row, D) += blocks[k].transpose();
    o.first = std::min(o.first, row);
  }
  for (size_t k = 0; k < on.size(); ++k) {
    const Clique<D>& q = tree.cliques[on[k].clique];
    const int f = on[k].first, n = q.F - f;
    if (n <= 0) continue;  // nothing reached this clique: Y_c = 0
    const auto LS = q.LS();
    auto Y = rowsOf(on[k]).bottomRows(n);
    LS.block(f, f, n, n).template triangularView<Eigen::Lower>().solveInPlace(Y);
    out.noalias() += Y.transpose() * Y;
    if (q.Sn == 0) continue;
    Rows pushed(by.data(), q.Sn, m);
    pushed.noalias() = LS.block(q.F, f, q.Sn, n) * Y;
    size_t j = k + 1;
    for (size_t b = 0; b < q.separator.size(); ++b) {
      const int s = q.separator[b], cs = tree.clique_of[s];
      if (j >= on.size() || on[j].clique != cs) j = find(k + 1, cs);
      if (j == on.size())
        throw std::logic_error("TreeMarginals: separator variable " + std::to_string(s) +
                               " is not frontal on the path");
      const int row = position(tree.cliques[cs], s) * D;
      rowsOf(on[j]).middleRows(row, D) -= pushed.middleRows(static_cast<int>(b) * D, D);
      on[j].first = std::min(on[j].first, row);
    }
  }
  return out;
}

template class TreeMarginals<3>;
template class TreeMarginals<6>;

}  // namespace arbor::bayestree
