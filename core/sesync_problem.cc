#include "arbor_slam/core/sesync_problem.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>
#include <string>

#include <Spectra/SymEigsSolver.h>
#include <Eigen/CholmodSupport>

#include "arbor_slam/core/information.h"

namespace arbor {

namespace {

using SpMat = Eigen::SparseMatrix<double>;
using Triplets = std::vector<Eigen::Triplet<double>>;

// Union–find root with path halving.
int findRoot(std::vector<int>& parent, int k) {
  while (parent[k] != k) {
    parent[k] = parent[parent[k]];
    k = parent[k];
  }
  return k;
}

// The first index not connected to index 0, or −1.
int firstDisconnected(int n, const std::vector<std::pair<int, int>>& links) {
  std::vector<int> parent(n);
  std::iota(parent.begin(), parent.end(), 0);
  for (const auto& [a, b] : links) parent[findRoot(parent, a)] = findRoot(parent, b);
  const int root = findRoot(parent, 0);
  for (int k = 1; k < n; ++k) {
    if (findRoot(parent, k) != root) return k;
  }
  return -1;
}

// Spectra operator x ↦ (S + ηI)⁻¹ x through a Cholesky factor.
struct InverseOp {
  using Scalar = double;
  const Eigen::CholmodSupernodalLLT<SpMat, Eigen::Lower>* chol;
  Eigen::Index n;
  Eigen::Index rows() const { return n; }
  Eigen::Index cols() const { return n; }
  void perform_op(const double* x, double* y) const {
    Eigen::Map<Eigen::VectorXd>(y, n) = chol->solve(Eigen::Map<const Eigen::VectorXd>(x, n));
  }
};

}  // namespace

template <class G>
void requireRelativePoseEdgesOnly(const PoseGraph<G>& graph) {
  if (!graph.hasPriors() && graph.custom_factors.empty()) return;
  if (!graph.custom_factors.empty())
    throw std::invalid_argument(
        "the certifiable solver takes relative-pose edges only: " +
        std::to_string(graph.custom_factors.size()) + " custom factor(s) (the first '" +
        graph.custom_factors.front().name() +
        "') are not supported by its relaxation; use Levenberg–Marquardt (--solver lm)");
  throw std::invalid_argument("the certifiable solver takes relative-pose edges only: " +
                              std::to_string(graph.pose_priors.size()) + " pose priors, " +
                              std::to_string(graph.position_priors.size()) +
                              " position priors; use --solver lm");
}

template void requireRelativePoseEdgesOnly(const PoseGraph<SE2>&);
template void requireRelativePoseEdgesOnly(const PoseGraph<SE3>&);

template <class G>
std::vector<SESyncMeasurement> sesyncMeasurements(const PoseGraph<G>& graph) {
  requireRelativePoseEdgesOnly(graph);
  constexpr int d = G::kDim;
  const int n = graph.numPoses();
  std::vector<SESyncMeasurement> out;
  out.reserve(graph.edges.size());
  std::vector<std::pair<int, int>> links;
  for (std::size_t k = 0; k < graph.edges.size(); ++k) {
    const auto& e = graph.edges[k];
    if (e.i < 0 || e.j < 0 || e.i >= n || e.j >= n) {
      throw std::invalid_argument("sesyncMeasurements: edge " + std::to_string(k) +
                                  " has a pose index out of range");
    }
    if (e.i == e.j) continue;
    const Eigen::MatrixXd iso = isotropicInformation(e.information, d);
    SESyncMeasurement m;
    m.i = e.i;
    m.j = e.j;
    m.R = e.measurement.rotation();
    m.t = e.measurement.translation();
    m.tau = iso(0, 0);
    m.kappa = d == 2 ? iso(d, d) : 0.5 * iso(d, d);  // SE-Sync's κ, see the header
    out.push_back(std::move(m));
    links.emplace_back(e.i, e.j);
  }
  if (n > 0) {
    const int bad = firstDisconnected(n, links);
    if (bad >= 0) {
      throw std::invalid_argument("SE-Sync: the pose graph is not connected: pose id " +
                                  std::to_string(graph.ids[bad]) + " is not reached from pose id " +
                                  std::to_string(graph.ids[0]));
    }
  }
  return out;
}

template std::vector<SESyncMeasurement> sesyncMeasurements(const PoseGraph<SE2>&);
template std::vector<SESyncMeasurement> sesyncMeasurements(const PoseGraph<SE3>&);

struct SESyncProblem::Factors {
  Eigen::CholmodDecomposition<SpMat, Eigen::Lower> L_red;         // L(W^τ) without node 0
  Eigen::CholmodDecomposition<SpMat, Eigen::Lower> precon;        // L(G̃ρ) + λI or M + λI
  mutable Eigen::CholmodSupernodalLLT<SpMat, Eigen::Lower> cert;  // M − Λ + ηI
  mutable bool cert_analyzed = false;
};

SESyncProblem::SESyncProblem(int n, int d, const std::vector<SESyncMeasurement>& measurements,
                             SESyncPreconditioner preconditioner, double max_condition)
    : n_(n), d_(d), preconditioner_(preconditioner), factors_(std::make_unique<Factors>()) {
  if (d != 2 && d != 3) throw std::invalid_argument("SESyncProblem: d must be 2 or 3");
  if (!(max_condition > 1)) {
    throw std::invalid_argument("SESyncProblem: max_condition must exceed 1");
  }
  if (n < 2) throw std::invalid_argument("SESyncProblem: needs at least 2 poses");
  std::vector<std::pair<int, int>> links;
  Triplets lrho, sigma, v, lw;
  for (std::size_t k = 0; k < measurements.size(); ++k) {
    const auto& m = measurements[k];
    const std::string where = "SESyncProblem: measurement " + std::to_string(k);
    if (m.i < 0 || m.j < 0 || m.i >= n || m.j >= n || m.i == m.j) {
      throw std::invalid_argument(where + " has bad pose indices");
    }
    if (m.R.rows() != d || m.R.cols() != d || m.t.size() != d) {
      throw std::invalid_argument(where + " has the wrong dimension");
    }
    if (!(m.kappa > 0) || !(m.tau > 0) || !std::isfinite(m.kappa) || !std::isfinite(m.tau) ||
        !m.R.allFinite() || !m.t.allFinite()) {
      throw std::invalid_argument(where + " has a non-positive or non-finite weight or value");
    }
    links.emplace_back(m.i, m.j);
    const int bi = d * m.i, bj = d * m.j;
    for (int a = 0; a < d; ++a) {
      lrho.emplace_back(bi + a, bi + a, m.kappa);
      lrho.emplace_back(bj + a, bj + a, m.kappa);
      for (int b = 0; b < d; ++b) {
        lrho.emplace_back(bi + a, bj + b, -m.kappa * m.R(a, b));
        lrho.emplace_back(bj + b, bi + a, -m.kappa * m.R(a, b));
        sigma.emplace_back(bi + a, bi + b, m.tau * m.t(a) * m.t(b));
      }
      v.emplace_back(m.i, bi + a, m.tau * m.t(a));
      v.emplace_back(m.j, bi + a, -m.tau * m.t(a));
    }
    lw.emplace_back(m.i, m.i, m.tau);
    lw.emplace_back(m.j, m.j, m.tau);
    lw.emplace_back(m.i, m.j, -m.tau);
    lw.emplace_back(m.j, m.i, -m.tau);
  }
  const int bad = firstDisconnected(n, links);
  if (bad >= 0) {
    throw std::invalid_argument("SESyncProblem: the measurement graph is not connected (pose " +
                                std::to_string(bad) + " not reached from pose 0)");
  }
  const int dn = d * n;
  L_rho_.resize(dn, dn);
  L_rho_.setFromTriplets(lrho.begin(), lrho.end());
  SpMat sigma_m(dn, dn);
  sigma_m.setFromTriplets(sigma.begin(), sigma.end());
  L_rho_sigma_ = L_rho_ + sigma_m;
  SpMat V(n, dn);
  V.setFromTriplets(v.begin(), v.end());
  SpMat LW(n, n);
  LW.setFromTriplets(lw.begin(), lw.end());
  V_red_ = V.bottomRows(n - 1);
  V_red_t_ = V_red_.transpose();
  const SpMat LW_red = LW.bottomRightCorner(n - 1, n - 1);

  // Full data matrix M = [L(W^τ) Ṽ; Ṽᵀ L(G̃ρ)+Σ̃] with every rotational diagonal block stored
  // in full (explicit zeros), so that M − blkdiag(0, Λ) + ηI has the pattern of M.
  Triplets mt;
  mt.reserve(LW.nonZeros() + 2 * V.nonZeros() + L_rho_sigma_.nonZeros() + n * d * d);
  for (int c = 0; c < n; ++c) {
    for (SpMat::InnerIterator it(LW, c); it; ++it) mt.emplace_back(it.row(), c, it.value());
  }
  for (int c = 0; c < dn; ++c) {
    for (SpMat::InnerIterator it(V, c); it; ++it) {
      mt.emplace_back(it.row(), n + c, it.value());
      mt.emplace_back(n + c, it.row(), it.value());
    }
    for (SpMat::InnerIterator it(L_rho_sigma_, c); it; ++it) {
      mt.emplace_back(n + it.row(), n + c, it.value());
    }
  }
  for (int i = 0; i < n; ++i) {
    for (int a = 0; a < d; ++a) {
      for (int b = 0; b < d; ++b) mt.emplace_back(n + d * i + a, n + d * i + b, 0.0);
    }
  }
  M_.resize(n + dn, n + dn);
  M_.setFromTriplets(mt.begin(), mt.end());

  factors_->L_red.compute(LW_red);
  if (factors_->L_red.info() != Eigen::Success) {
    throw std::runtime_error("SESyncProblem: the translational Laplacian is singular");
  }
  // λ = ‖P‖ / (max_condition − 1), ‖P‖ bounded by the largest absolute row sum (Gershgorin).
  SpMat P = preconditioner_ == SESyncPreconditioner::kDataMatrix ? M_ : L_rho_;
  Eigen::VectorXd row_sums = Eigen::VectorXd::Zero(P.rows());
  for (int c = 0; c < P.outerSize(); ++c) {
    for (SpMat::InnerIterator it(P, c); it; ++it) row_sums(it.row()) += std::abs(it.value());
  }
  const double lambda_reg = row_sums.maxCoeff() / (max_condition - 1);
  for (int k = 0; k < P.rows(); ++k) P.coeffRef(k, k) += lambda_reg;
  factors_->precon.compute(P);
  if (factors_->precon.info() != Eigen::Success) {
    throw std::runtime_error("SESyncProblem: the regularised data matrix could not be factored");
  }
}

SESyncProblem::~SESyncProblem() = default;

Eigen::MatrixXd SESyncProblem::Q(const Eigen::MatrixXd& X) const {
  const Eigen::MatrixXd W = factors_->L_red.solve(V_red_ * X);
  Eigen::MatrixXd out = L_rho_sigma_ * X;
  out.noalias() -= V_red_t_ * W;
  return out;
}

double SESyncProblem::objective(const Eigen::MatrixXd& X) const {
  return (X.cwiseProduct(Q(X))).sum();
}

Eigen::MatrixXd SESyncProblem::precondition(const Eigen::MatrixXd& V) const {
  if (preconditioner_ == SESyncPreconditioner::kConnectionLaplacian) {
    return factors_->precon.solve(V);
  }
  Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(n_ + d_ * n_, V.cols());
  rhs.bottomRows(d_ * n_) = V;
  const Eigen::MatrixXd Z = factors_->precon.solve(rhs);
  return Z.bottomRows(d_ * n_);
}

Eigen::MatrixXd SESyncProblem::lambdaBlocks(const Eigen::MatrixXd& X,
                                            const Eigen::MatrixXd& QX) const {
  Eigen::MatrixXd blocks(d_, d_ * n_);
  for (int i = 0; i < n_; ++i) {
    const Eigen::MatrixXd P = QX.middleRows(d_ * i, d_) * X.middleRows(d_ * i, d_).transpose();
    blocks.middleCols(d_ * i, d_) = 0.5 * (P + P.transpose());
  }
  return blocks;
}

Eigen::VectorXd SESyncProblem::certificateProduct(const Eigen::MatrixXd& lambda_blocks,
                                                  const Eigen::VectorXd& x) const {
  Eigen::VectorXd y = Q(x);
  for (int i = 0; i < n_; ++i) {
    y.segment(d_ * i, d_).noalias() -= lambda_blocks.middleCols(d_ * i, d_) * x.segment(d_ * i, d_);
  }
  return y;
}

bool SESyncProblem::verifyFullCertificate(const Eigen::MatrixXd& lambda_blocks, double eta,
                                          double* lambda_min, Eigen::VectorXd* direction) const {
  SpMat S = M_;
  for (int i = 0; i < n_; ++i) {
    for (int a = 0; a < d_; ++a) {
      for (int b = 0; b < d_; ++b) {
        S.coeffRef(n_ + d_ * i + a, n_ + d_ * i + b) -= lambda_blocks(a, d_ * i + b);
      }
    }
  }
  std::vector<double*> diagonal(S.rows());
  for (int k = 0; k < S.rows(); ++k) diagonal[k] = &S.coeffRef(k, k);
  auto& chol = factors_->cert;
  if (!factors_->cert_analyzed) {
    chol.cholmod().print = 0;  // a failed factorisation is an answer here, not an error
    chol.analyzePattern(S);
    factors_->cert_analyzed = true;
  }
  auto factorShifted = [&](double shift, double previous) {
    for (double* v : diagonal) *v += shift - previous;
    chol.factorize(S);
    return chol.info() == Eigen::Success;
  };
  const bool psd = factorShifted(eta, 0.0);
  double sigma = eta;
  if (!psd) {
    if (direction) direction->resize(0);
    if (!direction && !lambda_min) return false;
    // λ_min(S) ≥ −(largest absolute row sum) bounds how far σ must go.
    bool ok = false;
    for (int k = 0; k < 30 && !ok; ++k) {
      const double next = sigma * 10;
      ok = factorShifted(next, sigma);
      sigma = next;
    }
    if (!ok) return false;
  }
  // Shift-invert Lanczos: the largest eigenvalue θ of (S + σI)⁻¹ gives λ_min(S) = 1/θ − σ.
  InverseOp op{&chol, S.rows()};
  const Eigen::Index ncv = std::min<Eigen::Index>(20, S.rows());
  Spectra::SymEigsSolver<InverseOp> eigs(op, 1, ncv);
  eigs.init();
  eigs.compute(Spectra::SortRule::LargestAlge, 500, psd ? 1e-8 : 1e-6);
  const Eigen::VectorXd theta = eigs.eigenvalues();
  const bool found = theta.size() > 0 && theta(0) > 0;
  if (lambda_min) *lambda_min = found ? 1.0 / theta(0) - sigma : -sigma;
  if (!psd && direction && found) {
    const Eigen::VectorXd x = eigs.eigenvectors().col(0).tail(d_ * n_);
    if (x.norm() > 0) *direction = x.normalized();
  }
  return psd;
}

Eigen::MatrixXd SESyncProblem::recoverTranslations(const Eigen::MatrixXd& R) const {
  Eigen::MatrixXd T = Eigen::MatrixXd::Zero(n_, R.cols());
  T.bottomRows(n_ - 1) = -factors_->L_red.solve(V_red_ * R);
  return T;
}

}  // namespace arbor
