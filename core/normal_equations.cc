#include "arbor_slam/core/normal_equations.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>
#include <string>
#include <utility>

namespace arbor {
namespace {

template <class G>
void checkIndices(const PoseGraph<G>& graph) {
  const int n = graph.numPoses();
  for (int k = 0; k < graph.numEdges(); ++k) {
    const auto& e = graph.edges[k];
    if (e.i < 0 || e.i >= n || e.j < 0 || e.j >= n)
      throw std::invalid_argument("edge " + std::to_string(k) + " joins pose indices " +
                                  std::to_string(e.i) + " and " + std::to_string(e.j) +
                                  ", outside 0.." + std::to_string(n - 1));
  }
  const auto checkPriors = [n](const auto& priors, const char* what) {
    for (size_t k = 0; k < priors.size(); ++k)
      if (priors[k].i < 0 || priors[k].i >= n)
        throw std::invalid_argument(std::string(what) + " " + std::to_string(k) +
                                    " is on pose index " + std::to_string(priors[k].i) +
                                    ", outside 0.." + std::to_string(n - 1));
  };
  checkPriors(graph.pose_priors, "pose prior");
  checkPriors(graph.position_priors, "position prior");
  for (size_t k = 0; k < graph.custom_factors.size(); ++k) {
    const auto& c = graph.custom_factors[k];
    for (int key : {c.i, c.j})
      if ((key < 0 || key >= n) && (key == c.i || c.arity() == 2))
        throw std::invalid_argument("custom factor " + std::to_string(k) + " ('" + c.name() +
                                    "') is on pose index " + std::to_string(key) + ", outside 0.." +
                                    std::to_string(n - 1));
  }
  for (int g : graph.gaugeIndices())
    if (g < 0 || g >= n)
      throw std::invalid_argument("fixed pose index " + std::to_string(g) + " outside 0.." +
                                  std::to_string(n - 1));
}

template <class G>
std::string poseName(const PoseGraph<G>& graph, int p) {
  const std::string id = p < static_cast<int>(graph.ids.size()) ? std::to_string(graph.ids[p])
                                                                : "#" + std::to_string(p);
  return "pose id " + id;
}

// Above this many flops per factorisation, nested dissection is worth its ordering time.
constexpr double kNestedDissectionFlops = 1e8;

int findRoot(std::vector<int>& parent, int a) {
  while (parent[a] != a) a = parent[a] = parent[parent[a]];
  return a;
}

}  // namespace

template <class G>
std::string gaugeProblem(const PoseGraph<G>& graph) {
  checkIndices(graph);
  const int n = graph.numPoses();
  std::vector<int> parent(n);
  std::iota(parent.begin(), parent.end(), 0);
  for (const auto& e : graph.edges) parent[findRoot(parent, e.i)] = findRoot(parent, e.j);
  for (const auto& c : graph.custom_factors)
    if (c.arity() == 2) parent[findRoot(parent, c.i)] = findRoot(parent, c.j);
  // A component is anchored by a gauge pose or by priors that fix its gauge.
  std::vector<char> anchored(n, 0);
  for (int g : graph.gaugeIndices()) anchored[findRoot(parent, g)] = 1;
  if (graph.hasPriors() || !graph.custom_factors.empty()) {
    std::vector<GaugeInformation<G>> gauge(n);
    for (const auto& p : graph.pose_priors) gauge[findRoot(parent, p.i)].addPosePrior();
    for (const auto& p : graph.position_priors)
      gauge[findRoot(parent, p.i)].addPositionPrior(p.position, p.information);
    if (graph.poses.size() == static_cast<size_t>(n))
      for (const auto& c : graph.custom_factors)
        gauge[findRoot(parent, c.i)].addCustom(c, graph.poses);
    for (int p = 0; p < n; ++p)
      if (parent[p] == p && gauge[p].fixesGauge()) anchored[p] = 1;
  }
  int first = -1, count = 0;
  for (int p = 0; p < n; ++p) {
    if (anchored[findRoot(parent, p)]) continue;
    if (first < 0) first = p;
    ++count;
  }
  if (count == 0) return "";
  std::string what = poseName(graph, first);
  if (count > 1) what += " and " + std::to_string(count - 1) + " other pose(s)";
  return what +
         " not connected by edges to any fixed pose nor anchored by priors: the gauge is free "
         "there and the normal equations are singular";
}

template <class G>
NormalEquations<G>::NormalEquations(const PoseGraph<G>& graph, CholeskyBackend backend)
    : graph_(graph) {
  checkIndices(graph);
  const int n = graph.numPoses();
  constexpr int d = kDoF;

  // Variables: the non-gauge poses, first in pose order.
  var_of_pose_.assign(n, 0);
  for (int g : graph.gaugeIndices()) var_of_pose_[g] = -1;
  for (int p = 0; p < n; ++p)
    if (var_of_pose_[p] >= 0) var_of_pose_[p] = num_variables_++;

  // The off-diagonal blocks of H as (high, low) pairs, sorted by (high, low).
  const auto blockPairs = [&](const std::vector<int>& var) {
    std::vector<std::pair<int, int>> pairs;
    pairs.reserve(graph.edges.size());
    for (const auto& e : graph.edges) {
      const int a = var[e.i], b = var[e.j];
      if (a >= 0 && b >= 0 && a != b) pairs.emplace_back(std::max(a, b), std::min(a, b));
    }
    for (const auto& c : graph.custom_factors) {
      if (c.arity() < 2) continue;
      const int a = var[c.i], b = var[c.j];
      if (a >= 0 && b >= 0 && a != b) pairs.emplace_back(std::max(a, b), std::min(a, b));
    }
    std::sort(pairs.begin(), pairs.end());
    pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
    return pairs;
  };

  // A fill-reducing order of the blocks (cheaper than ordering scalars, keeps blocks whole); a
  // block flop is d³ scalar flops.
  {
    const auto pairs = blockPairs(var_of_pose_);
    SymmetricPattern blocks;  // upper triangle: column `high` holds the rows `low`
    blocks.n = num_variables_;
    blocks.col_ptr.assign(num_variables_ + 1, 0);
    for (const auto& pr : pairs) ++blocks.col_ptr[pr.first + 1];
    for (int c = 0; c < num_variables_; ++c) blocks.col_ptr[c + 1] += blocks.col_ptr[c] + 1;
    blocks.row_idx.reserve(blocks.col_ptr.back());
    auto it = pairs.begin();
    for (int c = 0; c < num_variables_; ++c) {
      for (; it != pairs.end() && it->first == c; ++it) blocks.row_idx.push_back(it->second);
      blocks.row_idx.push_back(c);
    }
    double block_flops = 0.0;
    const std::vector<int> order =
        fillReducingOrdering(blocks, kNestedDissectionFlops / (d * d * d), &block_flops);
    flops_ = block_flops * d * d * d;
    std::vector<int> position(num_variables_);
    for (int k = 0; k < num_variables_; ++k) position[order[k]] = k;
    pose_of_var_.assign(num_variables_, -1);
    for (int p = 0; p < n; ++p) {
      if (var_of_pose_[p] < 0) continue;
      var_of_pose_[p] = position[var_of_pose_[p]];
      pose_of_var_[var_of_pose_[p]] = p;
    }
  }

  const auto pairs = blockPairs(var_of_pose_);
  off_diagonal_.resize(pairs.size());
  for (size_t b = 0; b < pairs.size(); ++b) off_diagonal_[b] = {pairs[b].first, pairs[b].second};
  slots_.resize(graph.edges.size());
  for (size_t k = 0; k < graph.edges.size(); ++k)
    slotFor(graph.edges[k].i, graph.edges[k].j, pairs, &slots_[k]);
  linearization_.resize(graph.edges.size());
  custom_slots_.resize(graph.custom_factors.size());
  for (size_t k = 0; k < graph.custom_factors.size(); ++k)
    slotFor(graph.custom_factors[k].i, graph.custom_factors[k].j, pairs, &custom_slots_[k]);
  custom_linearization_.resize(graph.custom_factors.size());
  pose_prior_linearization_.resize(graph.pose_priors.size());
  for (size_t k = 0; k < graph.pose_priors.size(); ++k)
    pose_prior_linearization_[k].var = var_of_pose_[graph.pose_priors[k].i];
  position_prior_linearization_.resize(graph.position_priors.size());
  for (size_t k = 0; k < graph.position_priors.size(); ++k)
    position_prior_linearization_[k].var = var_of_pose_[graph.position_priors[k].i];
  diagonal_blocks_.assign(num_variables_, Block::Zero());
  off_diagonal_blocks_.assign(off_diagonal_.size(), Block::Zero());
  gradient_.setZero(dimension());
  hessian_diagonal_.setZero(dimension());

  backend_ = backend;
  if (backend_ == CholeskyBackend::kAuto)
    backend_ =
        flops_ <= kBlockCholeskyMaxFlops ? CholeskyBackend::kBlock : CholeskyBackend::kCholmod;
  if (num_variables_ == 0) return;
  if (backend_ == CholeskyBackend::kCholmod) {
    setUpCholmod();
    return;
  }
  std::vector<std::vector<int>> lower(num_variables_);
  for (const auto& b : off_diagonal_) lower[b.low].push_back(b.high);
  block_cholesky_ = std::make_unique<BlockCholesky<kDoF>>(lower);
  block_position_.resize(off_diagonal_.size());
  for (size_t b = 0; b < off_diagonal_.size(); ++b)
    block_position_[b] = block_cholesky_->find(off_diagonal_[b].high, off_diagonal_[b].low);
}

template <class G>
NormalEquations<G>::~NormalEquations() = default;

// Where a term on poses i and j (j −1: unary) goes among the sorted off-diagonal pairs.
template <class G>
void NormalEquations<G>::slotFor(int i, int j, const std::vector<std::pair<int, int>>& pairs,
                                 EdgeSlot* s) const {
  s->var_i = var_of_pose_[i];
  s->var_j = j < 0 ? -1 : var_of_pose_[j];
  if (s->var_i < 0 || s->var_j < 0 || s->var_i == s->var_j) return;
  const std::pair<int, int> key(std::max(s->var_i, s->var_j), std::min(s->var_i, s->var_j));
  s->off_diagonal =
      static_cast<int>(std::lower_bound(pairs.begin(), pairs.end(), key) - pairs.begin());
  s->i_is_high = s->var_i > s->var_j;
}

// H's upper triangle for CHOLMOD: scalar column c·d + q holds block column c's off-diagonal
// blocks (rows ascending), then the diagonal block's rows c·d .. c·d + q.
template <class G>
void NormalEquations<G>::setUpCholmod() {
  constexpr int d = kDoF;
  std::vector<int> blocks_in_column(num_variables_, 0);  // off-diagonal ones
  row_offset_.resize(off_diagonal_.size());
  for (size_t b = 0; b < off_diagonal_.size(); ++b)  // sorted by (high, low)
    row_offset_[b] = blocks_in_column[off_diagonal_[b].high]++ * d;
  SymmetricPattern pattern;
  pattern.n = dimension();
  pattern.col_ptr.assign(pattern.n + 1, 0);
  for (int c = 0; c < num_variables_; ++c)
    for (int q = 0; q < d; ++q)
      pattern.col_ptr[c * d + q + 1] = pattern.col_ptr[c * d + q] + blocks_in_column[c] * d + q + 1;
  pattern.row_idx.resize(pattern.col_ptr.back());
  for (size_t b = 0; b < off_diagonal_.size(); ++b) {
    const int c = off_diagonal_[b].high, row = off_diagonal_[b].low;
    for (int q = 0; q < d; ++q)
      for (int r = 0; r < d; ++r)
        pattern.row_idx[pattern.col_ptr[c * d + q] + row_offset_[b] + r] = row * d + r;
  }
  for (int c = 0; c < num_variables_; ++c)
    for (int q = 0; q < d; ++q)
      for (int r = 0; r <= q; ++r)
        pattern.row_idx[pattern.col_ptr[c * d + q + 1] - (q + 1) + r] = c * d + r;
  col_ptr_ = pattern.col_ptr;
  values_.assign(pattern.col_ptr.back(), 0.0);
  cholmod_ = std::make_unique<SparseCholesky>(std::move(pattern));
}

template <class G>
double NormalEquations<G>::hessianNonzeros() const {
  return static_cast<double>(off_diagonal_.size()) * kDoF * kDoF +
         static_cast<double>(num_variables_) * kDoF * (kDoF + 1) / 2;
}

template <class G>
double NormalEquations<G>::factorNonzeros() const {
  if (block_cholesky_) return block_cholesky_->nonzeros();
  return cholmod_ ? cholmod_->factorNonzeros() : 0.0;
}

template <class G>
double NormalEquations<G>::linearize(const std::vector<G>& poses) {
  constexpr int d = kDoF;
  if (static_cast<int>(poses.size()) != graph_.numPoses())
    throw std::invalid_argument("NormalEquations::linearize: " + std::to_string(poses.size()) +
                                " poses for a graph of " + std::to_string(graph_.numPoses()));
  for (auto& block : diagonal_blocks_) block.setZero();
  for (auto& block : off_diagonal_blocks_) block.setZero();
  gradient_.setZero();
  double f = 0.0;
  for (size_t k = 0; k < graph_.edges.size(); ++k) {
    const auto& edge = graph_.edges[k];
    const EdgeSlot& s = slots_[k];
    EdgeLinearization& lin = linearization_[k];
    edge.linearize(poses[edge.i], poses[edge.j], &lin.A_i, &lin.A_j, &lin.r);
    if (edge_weights_) {
      const double root = std::sqrt((*edge_weights_)[k]);
      lin.A_i *= root;
      lin.A_j *= root;
      lin.r *= root;
    }
    f += lin.r.squaredNorm();
    addTerms(s, lin);
  }
  f += linearizePriors(graph_.pose_priors, poses, &pose_prior_linearization_);
  f += linearizePriors(graph_.position_priors, poses, &position_prior_linearization_);
  for (size_t k = 0; k < graph_.custom_factors.size(); ++k) {
    EdgeLinearization& lin = custom_linearization_[k];
    graph_.custom_factors[k].linearize(poses, &lin.A_i, &lin.A_j, &lin.r);
    f += lin.r.squaredNorm();
    addTerms(custom_slots_[k], lin);
  }
  for (int c = 0; c < num_variables_; ++c)
    hessian_diagonal_.template segment<d>(c * d) = diagonal_blocks_[c].diagonal();
  return f;
}

template <class G>
void NormalEquations<G>::addTerms(const EdgeSlot& s, const EdgeLinearization& lin) {
  constexpr int d = kDoF;
  if (s.var_i >= 0 && s.var_i == s.var_j) {  // an edge from a pose to itself
    const Block a = lin.A_i + lin.A_j;
    diagonal_blocks_[s.var_i].noalias() += a.transpose() * a;
    gradient_.template segment<d>(s.var_i * d).noalias() += a.transpose() * lin.r;
    return;
  }
  if (s.var_i >= 0) {
    diagonal_blocks_[s.var_i].noalias() += lin.A_i.transpose() * lin.A_i;
    gradient_.template segment<d>(s.var_i * d).noalias() += lin.A_i.transpose() * lin.r;
  }
  if (s.var_j >= 0) {
    diagonal_blocks_[s.var_j].noalias() += lin.A_j.transpose() * lin.A_j;
    gradient_.template segment<d>(s.var_j * d).noalias() += lin.A_j.transpose() * lin.r;
  }
  if (s.off_diagonal >= 0) {
    Block& h = off_diagonal_blocks_[s.off_diagonal];
    if (s.i_is_high)
      h.noalias() += lin.A_i.transpose() * lin.A_j;
    else
      h.noalias() += lin.A_j.transpose() * lin.A_i;
  }
}

template <class G>
void NormalEquations<G>::setEdgeWeights(const std::vector<double>* weights) {
  if (weights && weights->size() != graph_.edges.size())
    throw std::invalid_argument(
        "NormalEquations::setEdgeWeights: " + std::to_string(weights->size()) + " weights for " +
        std::to_string(graph_.edges.size()) + " edges");
  edge_weights_ = weights;
}

// A unary prior on variable v: H(v, v) += AᵀA, g_v += Aᵀr; on a gauge pose only ‖r‖² (in F).
template <class G>
template <class Prior, class Linearization>
double NormalEquations<G>::linearizePriors(const std::vector<Prior>& priors,
                                           const std::vector<G>& poses,
                                           std::vector<Linearization>* out) {
  constexpr int d = kDoF;
  double f = 0.0;
  for (size_t k = 0; k < priors.size(); ++k) {
    Linearization& lin = (*out)[k];
    priors[k].linearize(poses[priors[k].i], &lin.A, &lin.r);
    f += lin.r.squaredNorm();
    if (lin.var < 0) continue;
    diagonal_blocks_[lin.var].noalias() += lin.A.transpose() * lin.A;
    gradient_.template segment<d>(lin.var * d).noalias() += lin.A.transpose() * lin.r;
  }
  return f;
}

// Σ ‖r + A δ_v‖² (with_residual) or Σ ‖A δ_v‖² over one kind of prior.
template <class G>
template <class Linearization>
double NormalEquations<G>::priorModelCost(const std::vector<Linearization>& lin,
                                          const Eigen::VectorXd& delta, bool with_residual) const {
  constexpr int d = kDoF;
  double f = 0.0;
  for (const Linearization& l : lin) {
    if (l.var < 0) {
      if (with_residual) f += l.r.squaredNorm();
      continue;
    }
    const auto w = (l.A * delta.template segment<d>(l.var * d)).eval();
    f += with_residual ? (w + l.r).squaredNorm() : w.squaredNorm();
  }
  return f;
}

template <class G>
void NormalEquations<G>::loadBlocks(const Eigen::VectorXd* damping) {
  constexpr int d = kDoF;
  BlockCholesky<kDoF>& l = *block_cholesky_;
  l.setOffDiagonalZero();
  for (size_t b = 0; b < off_diagonal_blocks_.size(); ++b)
    l.offDiagonal(block_position_[b]) = off_diagonal_blocks_[b];
  for (int c = 0; c < num_variables_; ++c) {
    l.diagonal(c) = diagonal_blocks_[c];
    if (damping) l.diagonal(c).diagonal() += damping->template segment<d>(c * d);
  }
}

template <class G>
void NormalEquations<G>::loadCholmod(const Eigen::VectorXd* damping) {
  constexpr int d = kDoF;
  for (size_t b = 0; b < off_diagonal_blocks_.size(); ++b) {
    const Block& h = off_diagonal_blocks_[b];  // H(high, low); CHOLMOD wants H(low, high)
    const int c = off_diagonal_[b].high;
    for (int q = 0; q < d; ++q)
      Eigen::Map<Vector>(values_.data() + col_ptr_[c * d + q] + row_offset_[b]) =
          h.row(q).transpose();
  }
  for (int c = 0; c < num_variables_; ++c) {
    const Block& block = diagonal_blocks_[c];
    for (int q = 0; q < d; ++q) {
      double* column = values_.data() + col_ptr_[c * d + q + 1] - (q + 1);
      for (int r = 0; r <= q; ++r) column[r] = block(r, q);
      if (damping) column[q] += (*damping)(c * d + q);
    }
  }
}

template <class G>
bool NormalEquations<G>::factorize(const Eigen::VectorXd* damping) {
  failed_column_ = -1;
  if (num_variables_ == 0) return true;
  if (damping && damping->size() != dimension())
    throw std::invalid_argument("NormalEquations::factorize: damping of size " +
                                std::to_string(damping->size()) + ", expected " +
                                std::to_string(dimension()));
  if (block_cholesky_) {
    loadBlocks(damping);
    if (block_cholesky_->factorize()) return true;
    failed_column_ = block_cholesky_->failedBlock() * kDoF;
    return false;
  }
  loadCholmod(damping);
  if (cholmod_->factorize(values_.data())) return true;
  failed_column_ = cholmod_->failedColumn();
  return false;
}

template <class G>
std::string NormalEquations<G>::factorizationFailure() const {
  if (failed_column_ < 0 || failed_column_ >= dimension()) return "";
  return "the normal equations are not positive definite (Cholesky failed at " +
         poseName(graph_, pose_of_var_[failed_column_ / kDoF]) + ")";
}

template <class G>
void NormalEquations<G>::solve(const Eigen::VectorXd& b, Eigen::VectorXd* x) {
  if (num_variables_ == 0) {
    x->resize(0);
  } else if (block_cholesky_) {
    block_cholesky_->solve(b, x);
  } else {
    cholmod_->solve(b, x);
  }
}

// Σ ‖r + A_i δ_i + A_j δ_j‖² (with_residual) or Σ ‖A_i δ_i + A_j δ_j‖² over binary terms.
template <class G>
double NormalEquations<G>::slotModelCost(const std::vector<EdgeSlot>& slots,
                                         const std::vector<EdgeLinearization>& lin,
                                         const Eigen::VectorXd& delta, bool with_residual) const {
  constexpr int d = kDoF;
  double f = 0.0;
  for (size_t k = 0; k < slots.size(); ++k) {
    const EdgeSlot& s = slots[k];
    Vector v = with_residual ? lin[k].r : Vector::Zero();
    if (s.var_i >= 0) v.noalias() += lin[k].A_i * delta.template segment<d>(s.var_i * d);
    if (s.var_j >= 0) v.noalias() += lin[k].A_j * delta.template segment<d>(s.var_j * d);
    f += v.squaredNorm();
  }
  return f;
}

template <class G>
double NormalEquations<G>::modelCost(const Eigen::VectorXd& delta) const {
  double f = slotModelCost(slots_, linearization_, delta, true);
  f += priorModelCost(pose_prior_linearization_, delta, true);
  f += priorModelCost(position_prior_linearization_, delta, true);
  f += slotModelCost(custom_slots_, custom_linearization_, delta, true);
  return f;
}

template <class G>
double NormalEquations<G>::jacobianSquaredNorm(const Eigen::VectorXd& v) const {
  double f = slotModelCost(slots_, linearization_, v, false);
  f += priorModelCost(pose_prior_linearization_, v, false);
  f += priorModelCost(position_prior_linearization_, v, false);
  f += slotModelCost(custom_slots_, custom_linearization_, v, false);
  return f;
}

template <class G>
void NormalEquations<G>::retract(const std::vector<G>& poses, const Eigen::VectorXd& delta,
                                 std::vector<G>* out) const {
  constexpr int d = kDoF;
  out->resize(poses.size());
  for (size_t p = 0; p < poses.size(); ++p) {
    const int v = var_of_pose_[p];
    (*out)[p] = v < 0 ? poses[p] : poses[p].retract(delta.template segment<d>(v * d));
  }
}

template <class G>
std::vector<typename G::Tangent> NormalEquations<G>::perPose(const Eigen::VectorXd& delta) const {
  constexpr int d = kDoF;
  std::vector<typename G::Tangent> out(var_of_pose_.size(), G::Tangent::Zero());
  for (size_t p = 0; p < var_of_pose_.size(); ++p)
    if (var_of_pose_[p] >= 0) out[p] = delta.template segment<d>(var_of_pose_[p] * d);
  return out;
}

template std::string gaugeProblem(const PoseGraph<SE2>&);
template std::string gaugeProblem(const PoseGraph<SE3>&);
template class NormalEquations<SE2>;
template class NormalEquations<SE3>;

}  // namespace arbor
