#include "arbor/bayestree/marginals.h"

#include <algorithm>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <utility>

#include <Eigen/Core>

namespace arbor::bayestree {

template <int D>
void TreeMarginals<D>::clear() {
  for (int c : cached_) {
    cache_[c].joint.resize(0, 0);
    cache_[c].X.resize(0, 0);
  }
  cached_.clear();
}

template <int D>
void TreeMarginals<D>::sync(const BayesTree<D>& tree, long version) {
  if (version != version_) {
    clear();
    version_ = version;
  }
  cache_.resize(tree.cliques.size());
  mark_.resize(tree.cliques.size(), 0);
}

template <int D>
int TreeMarginals<D>::position(const Clique<D>& c, int v) {
  const auto f = std::find(c.frontals.begin(), c.frontals.end(), v);
  if (f != c.frontals.end()) return static_cast<int>(f - c.frontals.begin());
  const auto s = std::find(c.separator.begin(), c.separator.end(), v);
  if (s != c.separator.end())
    return static_cast<int>(c.frontals.size() + (s - c.separator.begin()));
  throw std::logic_error("TreeMarginals: variable " + std::to_string(v) + " not in its clique");
}

// (1) for clique c: X = R⁻¹S = L⁻ᵀBᵀ with [L; B] = [Rᵀ; Sᵀ] as stored, (RᵀR)⁻¹ = L⁻ᵀL⁻¹,
// Σ_ss gathered from the parent's joint, Σ_fs = −X Σ_ss, Σ_ff = (RᵀR)⁻¹ − Σ_fs Xᵀ.
template <int D>
void TreeMarginals<D>::jointOf(const BayesTree<D>& tree, int c, const Eigen::MatrixXd* parent,
                               Eigen::MatrixXd* joint, Eigen::MatrixXd* X) {
  const Clique<D>& k = tree.cliques[c];
  const int F = k.F, Sn = k.Sn;
  const auto L = k.LS().topRows(F).template triangularView<Eigen::Lower>();
  Eigen::MatrixXd Linv = Eigen::MatrixXd::Identity(F, F);
  L.solveInPlace(Linv);  // L⁻¹, lower triangular
  joint->resize(F + Sn, F + Sn);
  joint->topLeftCorner(F, F).noalias() =
      Linv.template triangularView<Eigen::Lower>().transpose() * Linv;
  if (Sn == 0) return;
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
  joint->topLeftCorner(F, F).noalias() -= Sfs * X->transpose();
  joint->bottomLeftCorner(Sn, F) = Sfs.transpose();
}

template <int D>
const Eigen::MatrixXd& TreeMarginals<D>::cliqueJoint(const BayesTree<D>& tree, int c) {
  // Up to the first clique with a cached joint (or past the root), then (1) top-down.
  path_.clear();
  for (int p = c; p >= 0 && cache_[p].joint.size() == 0; p = tree.cliques[p].parent)
    path_.push_back(p);
  for (auto it = path_.rbegin(); it != path_.rend(); ++it) {
    const int parent = tree.cliques[*it].parent;
    Entry& e = cache_[*it];
    jointOf(tree, *it, parent >= 0 ? &cache_[parent].joint : nullptr, &e.joint, &e.X);
    cached_.push_back(*it);
  }
  return cache_[c].joint;
}

// x_v from its clique c up to l's child: x_f = −X x_s + noise at each clique on the way, the
// separator variables passed through; T maps the current variables V to x_v.
template <int D>
void TreeMarginals<D>::shortcut(const BayesTree<D>& tree, int v, int c, int l, std::vector<int>* V,
                                Eigen::MatrixXd* T) {
  if (c == l) {
    V->assign(1, v);
    *T = Eigen::MatrixXd::Identity(D, D);
    return;
  }
  const Clique<D>& k = tree.cliques[c];
  *V = k.separator;
  *T = -cache_[c].X.middleRows(position(k, v) * D, D);
  for (int p = k.parent; p != l; p = tree.cliques[p].parent) {
    const Clique<D>& q = tree.cliques[p];
    const int nf = static_cast<int>(q.frontals.size());
    Eigen::MatrixXd next = Eigen::MatrixXd::Zero(D, q.Sn);
    for (size_t j = 0; j < V->size(); ++j) {
      const int at = position(q, (*V)[j]);
      const auto Tj = T->middleCols(static_cast<int>(j) * D, D);
      if (at >= nf)
        next.middleCols((at - nf) * D, D) += Tj;
      else
        next.noalias() -= Tj * cache_[p].X.middleRows(at * D, D);
    }
    *V = q.separator;
    T->swap(next);
  }
}

// (2): Σ_vv = YᵀY, Y = R⁻ᵀE_v, by forward substitution along the path from v's clique to the
// root. Per clique c, bottom-up, with [L; B] = [Rᵀ; Sᵀ] as stored: L y_c = r_c, then
// r_s −= B y_c for the separator's rows (frontal rows of cliques above on the path).
template <int D>
typename TreeMarginals<D>::Block TreeMarginals<D>::pathMarginal(const BayesTree<D>& tree, int v) {
  using Rows = Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, D>>;
  // The path, each clique's rows in one buffer (offset_ per path entry), and each frontal's row
  // in it (row_of_ per variable), so a separator variable finds its rows in O(1).
  path_.clear();
  offset_.clear();
  int rows = 0, max_sn = 0;
  for (int p = tree.clique_of[v]; p >= 0; p = tree.cliques[p].parent) {
    const Clique<D>& q = tree.cliques[p];
    path_.push_back(p);
    offset_.push_back(rows);
    row_of_.resize(std::max(row_of_.size(), tree.clique_of.size()), -1);
    for (size_t f = 0; f < q.frontals.size(); ++f)
      row_of_[q.frontals[f]] = rows + static_cast<int>(f) * D;
    rows += q.F;
    max_sn = std::max(max_sn, q.Sn);
  }
  buffer_.assign(static_cast<size_t>(rows + max_sn) * D, 0.0);
  Rows r(buffer_.data(), rows, D);  // r_c, then y_c, per clique of the path
  r.template middleRows<D>(row_of_[v]).setIdentity();
  Block sigma = Block::Zero();
  bool off_path = false;
  for (size_t k = 0; k < path_.size() && !off_path; ++k) {
    const Clique<D>& q = tree.cliques[path_[k]];
    auto y = r.middleRows(offset_[k], q.F);
    q.LS().topRows(q.F).template triangularView<Eigen::Lower>().solveInPlace(y);
    sigma.noalias() += y.transpose() * y;
    if (q.Sn == 0) continue;
    Rows By(buffer_.data() + static_cast<size_t>(rows) * D, q.Sn, D);
    By.noalias() = q.LS().bottomRows(q.Sn) * y;
    for (size_t b = 0; b < q.separator.size(); ++b) {
      const int at = row_of_[q.separator[b]];
      if (at < 0) {
        off_path = true;
        break;
      }
      r.template middleRows<D>(at) -= By.template middleRows<D>(static_cast<int>(b) * D);
    }
  }
  for (int c : path_)
    for (int f : tree.cliques[c].frontals) row_of_[f] = -1;
  if (off_path)
    throw std::logic_error("TreeMarginals: a separator variable of variable " + std::to_string(v) +
                           "'s path is not frontal on it");
  return sigma;
}

template <int D>
typename TreeMarginals<D>::Block TreeMarginals<D>::marginal(const BayesTree<D>& tree, long version,
                                                            int v) {
  std::lock_guard<std::mutex> lock(mutex_);
  const int c = tree.clique_of[v];
  // A clique whose joint is cached for this version (by joint()) answers at once; else the path
  // solve (2), which costs O(Σ (F² + F·Sn) D) on the path instead of the joints'
  // O(Σ (F + Sn)³), and leaves the cache as it is.
  if (version == version_ && c < static_cast<int>(cache_.size()) && cache_[c].joint.size() != 0) {
    const int at = position(tree.cliques[c], v) * D;
    return cache_[c].joint.template block<D, D>(at, at);
  }
  return pathMarginal(tree, v);
}

template <int D>
typename TreeMarginals<D>::JointBlock TreeMarginals<D>::joint(const BayesTree<D>& tree,
                                                              long version, int a, int b) {
  std::lock_guard<std::mutex> lock(mutex_);
  sync(tree, version);
  JointBlock out = JointBlock::Zero();
  const int ca = tree.clique_of[a], cb = tree.clique_of[b];
  if (ca >= 0) {
    const int at = position(tree.cliques[ca], a) * D;
    out.template topLeftCorner<D, D>() = cliqueJoint(tree, ca).template block<D, D>(at, at);
  }
  if (cb >= 0) {
    const int at = position(tree.cliques[cb], b) * D;
    out.template bottomRightCorner<D, D>() = cliqueJoint(tree, cb).template block<D, D>(at, at);
  }
  if (ca < 0 || cb < 0) return out;  // a constant: no correlation
  // The lowest common ancestor l (none: different trees, independent).
  if (++mark_stamp_ == 0) {
    std::fill(mark_.begin(), mark_.end(), 0);
    mark_stamp_ = 1;
  }
  for (int p = ca; p >= 0; p = tree.cliques[p].parent) mark_[p] = mark_stamp_;
  int l = cb;
  while (l >= 0 && mark_[l] != mark_stamp_) l = tree.cliques[l].parent;
  if (l < 0) return out;
  std::vector<int> Va, Vb;
  Eigen::MatrixXd Ta, Tb;
  shortcut(tree, a, ca, l, &Va, &Ta);
  shortcut(tree, b, cb, l, &Vb, &Tb);
  const Eigen::MatrixXd& J = cache_[l].joint;  // cached: l is on both paths
  const Clique<D>& k = tree.cliques[l];
  Eigen::MatrixXd Sl(Va.size() * D, Vb.size() * D);
  for (size_t i = 0; i < Va.size(); ++i) {
    const int pi = position(k, Va[i]) * D;
    for (size_t j = 0; j < Vb.size(); ++j)
      Sl.template block<D, D>(static_cast<int>(i) * D, static_cast<int>(j) * D) =
          J.template block<D, D>(pi, position(k, Vb[j]) * D);
  }
  const Block ab = Ta * Sl * Tb.transpose();
  out.template topRightCorner<D, D>() = ab;
  out.template bottomLeftCorner<D, D>() = ab.transpose();
  return out;
}

// Depth first from the roots; a clique's joint is kept until its last child has read it, so the
// memory held is that of the cliques on the current path and their waiting siblings' parents.
template <int D>
void TreeMarginals<D>::all(const BayesTree<D>& tree, std::vector<Block>* out) {
  const int nc = static_cast<int>(tree.cliques.size());
  std::vector<Eigen::MatrixXd> joint(nc);
  std::vector<int> waiting(nc, 0);
  std::vector<int> stack(tree.roots.begin(), tree.roots.end());
  Eigen::MatrixXd X;
  auto release = [&](int c) {  // c and every ancestor whose children are all done
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
    for (size_t a = 0; a < k.frontals.size(); ++a)
      (*out)[k.frontals[a]] =
          joint[c].template block<D, D>(static_cast<int>(a) * D, static_cast<int>(a) * D);
    waiting[c] = static_cast<int>(k.children.size());
    for (int ch : k.children) stack.push_back(ch);
    release(c);
  }
}

template <int D>
int TreeMarginals<D>::cachedCliques() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return static_cast<int>(cached_.size());
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
  const int m = blocks.empty() ? 0 : static_cast<int>(blocks.front().rows());
  Eigen::MatrixXd out = Eigen::MatrixXd::Zero(m, m);
  // The cliques on the paths, each once, deepest first.
  std::vector<std::pair<int, int>> order;        // (−depth, clique)
  std::unordered_map<int, Eigen::MatrixXd> rhs;  // variable → its rows of Aᵀ − pushed terms
  for (size_t k = 0; k < vars.size(); ++k) {
    const int v = vars[k];
    if (v < 0 || v >= static_cast<int>(tree.clique_of.size()) || tree.clique_of[v] < 0) continue;
    auto [it, fresh] = rhs.try_emplace(v, Eigen::MatrixXd::Zero(D, m));
    it->second += blocks[k].transpose();
    std::vector<int> path;
    for (int c = tree.clique_of[v]; c >= 0; c = tree.cliques[c].parent) path.push_back(c);
    for (size_t q = 0; q < path.size(); ++q)
      order.emplace_back(-static_cast<int>(path.size() - 1 - q), path[q]);
  }
  std::sort(order.begin(), order.end());
  order.erase(std::unique(order.begin(), order.end()), order.end());
  Eigen::MatrixXd Y, pushed;
  for (const auto& [depth, c] : order) {
    const Clique<D>& k = tree.cliques[c];
    const int nf = static_cast<int>(k.frontals.size());
    Y = Eigen::MatrixXd::Zero(k.F, m);
    bool any = false;
    for (int f = 0; f < nf; ++f) {
      auto it = rhs.find(k.frontals[f]);
      if (it == rhs.end()) continue;
      Y.middleRows(f * D, D) = it->second;
      any = true;
    }
    if (!any) continue;
    k.LS().topRows(k.F).template triangularView<Eigen::Lower>().solveInPlace(Y);
    out.noalias() += Y.transpose() * Y;
    if (k.Sn == 0) continue;
    pushed.noalias() = k.LS().bottomRows(k.Sn) * Y;
    for (size_t b = 0; b < k.separator.size(); ++b) {
      auto [it, fresh] = rhs.try_emplace(k.separator[b], Eigen::MatrixXd::Zero(D, m));
      it->second -= pushed.middleRows(static_cast<int>(b) * D, D);
    }
  }
  return out;
}

template class TreeMarginals<3>;
template class TreeMarginals<6>;

}  // namespace arbor::bayestree
