// Chordal initialisation: rotations by the chordal relaxation of Carlone et al., "Initialization
// techniques for 3D SLAM: a survey on rotation estimation and its use in pose graph
// optimization" (ICRA 2015), §III-B (and Carlone et al. 2014 for 2D), then translations by
// linear least squares with the rotations held (ibid., §IV, "two-stage" initialisation).
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/CholmodSupport>
#include <Eigen/Core>
#include <Eigen/SVD>
#include <Eigen/SparseCore>

#include "arbor_slam/core/initialization.h"
#include "arbor_slam/core/initialization_internal.h"

namespace arbor {
namespace {

using Triplets = std::vector<Eigen::Triplet<double>>;

/// Solves A X = B for a sparse symmetric positive-definite A given by its lower triangle.
Eigen::MatrixXd solveSymmetric(int size, const Triplets& lower, const Eigen::MatrixXd& rhs,
                               const std::string& what) {
  Eigen::SparseMatrix<double> A(size, size);
  A.setFromTriplets(lower.begin(), lower.end());
  Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double>, Eigen::Lower> solver;
  solver.compute(A);
  if (solver.info() != Eigen::Success) {
    throw std::runtime_error("chordal initialisation: the " + what +
                             " system is not positive definite (CHOLMOD factorisation failed)");
  }
  Eigen::MatrixXd x = solver.solve(rhs);
  if (solver.info() != Eigen::Success || !x.allFinite()) {
    throw std::runtime_error("chordal initialisation: solving the " + what + " system failed");
  }
  return x;
}

/// Appends the block M at block position (a, b), a > b, of a matrix with d×d blocks.
template <int d>
void addBlock(int a, int b, const Eigen::Matrix<double, d, d>& M, Triplets* out) {
  for (int q = 0; q < d; ++q) {
    for (int p = 0; p < d; ++p) out->emplace_back(a * d + p, b * d + q, M(p, q));
  }
}

/// Appends the lower triangle of the diagonal block M at (a, a).
template <int d>
void addDiagonalBlock(int a, const Eigen::Matrix<double, d, d>& M, Triplets* out) {
  for (int q = 0; q < d; ++q) {
    for (int p = q; p < d; ++p) out->emplace_back(a * d + p, a * d + q, M(p, q));
  }
}

/// The nearest rotation (Frobenius norm): SO(2) in closed form, SO(3) by SVD with det +1.
Eigen::Matrix2d projectToRotation(const Eigen::Matrix2d& M) {
  // max over θ of tr(R(θ)ᵀ M) = cos θ (m₀₀ + m₁₁) + sin θ (m₁₀ − m₀₁).
  const double theta = std::atan2(M(1, 0) - M(0, 1), M(0, 0) + M(1, 1));
  return SE2(0.0, 0.0, theta).rotation();
}

Eigen::Matrix3d projectToRotation(const Eigen::Matrix3d& M) {
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(M, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d U = svd.matrixU();
  if ((U * svd.matrixV().transpose()).determinant() < 0.0) U.col(2) = -U.col(2);
  return U * svd.matrixV().transpose();
}

/// κ = r / tr(Ω_rr⁻¹), the isotropic rotational precision of isotropicInformation.
template <class G>
double rotationalPrecision(const PoseGraph<G>& graph, int edge_id) {
  constexpr int r = G::kDoF - G::kDim;
  const auto& e = graph.edges[edge_id];
  const Eigen::Matrix<double, r, r> block = e.information.template bottomRightCorner<r, r>();
  const Eigen::LLT<Eigen::Matrix<double, r, r>> llt(block);
  if (llt.info() != Eigen::Success) {
    throw std::invalid_argument("chordal initialisation: edge " + std::to_string(edge_id) + " (" +
                                std::to_string(graph.ids[e.i]) + " → " +
                                std::to_string(graph.ids[e.j]) +
                                "): the rotational block of its information is not positive "
                                "definite");
  }
  const Eigen::Matrix<double, r, r> cov = llt.solve(Eigen::Matrix<double, r, r>::Identity());
  return r / cov.trace();
}

/// Rotations of the free poses (var[k] ≥ 0) by chordal relaxation, the others held: rows of
/// Rⱼ − Rᵢ Z are (yⱼ − Zᵀ yᵢ)ᵀ with y a row of R as a column, so all d rows share one normal
/// matrix, solved for Yₖ = Rₖᵀ with d right-hand sides; each block is then projected to SO(d).
template <class G>
void solveRotations(const PoseGraph<G>& graph, const std::vector<int>& var, int num_free,
                    std::vector<Eigen::Matrix<double, G::kDim, G::kDim>>* rotations) {
  constexpr int d = G::kDim;
  using MatD = Eigen::Matrix<double, d, d>;
  std::vector<MatD>& R = *rotations;
  Triplets lower;
  lower.reserve(static_cast<std::size_t>(graph.numEdges() + num_free) * d * d);
  std::vector<double> diagonal(num_free, 0.0);  // the diagonal blocks are κ I
  Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(num_free * d, d);
  for (int id = 0; id < graph.numEdges(); ++id) {
    const auto& e = graph.edges[id];
    const int vi = var[e.i], vj = var[e.j];
    if (e.i == e.j || (vi < 0 && vj < 0)) continue;
    const double kappa = rotationalPrecision(graph, id);
    const MatD Z = e.measurement.rotation();
    if (vi >= 0) diagonal[vi] += kappa;  // κ Z Zᵀ = κ I
    if (vj >= 0) diagonal[vj] += kappa;
    if (vi >= 0 && vj >= 0) {
      if (vi > vj) {
        addBlock<d>(vi, vj, -kappa * Z, &lower);
      } else {
        addBlock<d>(vj, vi, -kappa * Z.transpose(), &lower);
      }
    } else if (vi < 0) {
      rhs.middleRows<d>(vj * d) += kappa * Z.transpose() * R[e.i].transpose();
    } else {
      rhs.middleRows<d>(vi * d) += kappa * Z * R[e.j].transpose();
    }
  }
  for (int v = 0; v < num_free; ++v) {
    for (int p = 0; p < d; ++p) lower.emplace_back(v * d + p, v * d + p, diagonal[v]);
  }
  const Eigen::MatrixXd Y = solveSymmetric(num_free * d, lower, rhs, "rotation");
  for (std::size_t k = 0; k < var.size(); ++k) {
    if (var[k] >= 0) R[k] = projectToRotation(MatD(Y.middleRows<d>(var[k] * d).transpose()));
  }
}

/// True if every edge has Ω_tt = τ I (to 1e-12 relative): the translation system then splits
/// into one scalar system per coordinate.
template <class G>
bool translationInformationIsotropic(const PoseGraph<G>& graph) {
  constexpr int d = G::kDim;
  for (const auto& e : graph.edges) {
    const Eigen::Matrix<double, d, d> block = e.information.template topLeftCorner<d, d>();
    const double tau = block.trace() / d;
    if ((block - tau * Eigen::Matrix<double, d, d>::Identity()).cwiseAbs().maxCoeff() >
        1e-12 * std::abs(tau)) {
      return false;
    }
  }
  return true;
}

/// Translations with the rotations R held: min Σ ‖tⱼ − tᵢ − Rᵢ t_z‖²_W over the free poses
/// (var[k] ≥ 0), gauge translations fixed. The residual is (Rᵢ Z) times the translational error
/// of the edge, so W = (Rᵢ Z) Ω_tt (Rᵢ Z)ᵀ. Unknown blocks of size B: B = d (one right-hand
/// side), or B = 1 when every Ω_tt = τ I (W = τ I; d right-hand sides, one per coordinate).
template <int B, class G>
void solveTranslations(const PoseGraph<G>& graph, const std::vector<int>& var, int num_free,
                       const std::vector<Eigen::Matrix<double, G::kDim, G::kDim>>& R,
                       std::vector<Eigen::Matrix<double, G::kDim, 1>>* t) {
  constexpr int d = G::kDim;
  using MatD = Eigen::Matrix<double, d, d>;
  using VecD = Eigen::Matrix<double, d, 1>;
  using MatB = Eigen::Matrix<double, B, B>;
  Triplets lower;
  lower.reserve(static_cast<std::size_t>(graph.numEdges() + num_free) * B * B);
  std::vector<MatB> diagonal(num_free, MatB::Zero());
  Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(num_free * B, d / B);
  auto addRhs = [&](int v, const VecD& w) {
    if constexpr (B == 1) {
      rhs.row(v) += w.transpose();
    } else {
      rhs.col(0).segment<d>(v * d) += w;
    }
  };
  for (const auto& e : graph.edges) {
    const int vi = var[e.i], vj = var[e.j];
    if (e.i == e.j || (vi < 0 && vj < 0)) continue;
    const MatD omega_t = e.information.template topLeftCorner<d, d>();
    MatD W;
    if constexpr (B == 1) {
      W = (omega_t.trace() / d) * MatD::Identity();
    } else {
      const MatD Rw = R[e.i] * e.measurement.rotation();
      W = Rw * omega_t * Rw.transpose();
    }
    const MatB Wb = W.template topLeftCorner<B, B>();
    const VecD u = R[e.i] * e.measurement.translation();
    if (vi >= 0) diagonal[vi] += Wb;
    if (vj >= 0) diagonal[vj] += Wb;
    if (vi >= 0 && vj >= 0) {
      addBlock<B>(std::max(vi, vj), std::min(vi, vj), -Wb, &lower);
      addRhs(vj, W * u);
      addRhs(vi, -(W * u));
    } else if (vi < 0) {
      addRhs(vj, W * ((*t)[e.i] + u));
    } else {
      addRhs(vi, W * ((*t)[e.j] - u));
    }
  }
  for (int v = 0; v < num_free; ++v) addDiagonalBlock<B>(v, diagonal[v], &lower);
  const Eigen::MatrixXd x = solveSymmetric(num_free * B, lower, rhs, "translation");
  for (std::size_t k = 0; k < var.size(); ++k) {
    if (var[k] < 0) continue;
    if constexpr (B == 1) {
      (*t)[k] = x.row(var[k]).transpose();
    } else {
      (*t)[k] = x.col(0).segment<d>(var[k] * d);
    }
  }
}

}  // namespace

template <class G>
std::vector<G> chordalInitialization(const PoseGraph<G>& graph) {
  constexpr int d = G::kDim;
  using MatD = Eigen::Matrix<double, d, d>;
  using VecD = Eigen::Matrix<double, d, 1>;
  const std::string where = "chordal initialisation";

  init_detail::validateGraph(graph, where);
  const int n = graph.numPoses();
  if (n == 0) return {};
  const init_detail::Adjacency adj = init_detail::buildAdjacency(graph);
  const init_detail::Roots<G> roots = init_detail::findRoots(graph, where);
  init_detail::requireConnected(graph, adj, roots, where);

  // var[k]: the block of pose k among the unknowns, or −1 for a gauge root.
  std::vector<int> var(n, 0);
  std::vector<MatD> R(n, MatD::Identity());
  std::vector<VecD> t(n, VecD::Zero());
  std::vector<G> x(n);
  for (std::size_t r = 0; r < roots.poses.size(); ++r) {
    const int k = roots.poses[r];
    var[k] = -1;
    x[k] = roots.values[r];
    R[k] = x[k].rotation();
    t[k] = x[k].translation();
  }
  int num_free = 0;
  for (int k = 0; k < n; ++k) {
    if (var[k] == 0) var[k] = num_free++;
  }
  if (num_free > 0) {
    solveRotations(graph, var, num_free, &R);
    if (translationInformationIsotropic(graph)) {
      solveTranslations<1>(graph, var, num_free, R, &t);
    } else {
      solveTranslations<d>(graph, var, num_free, R, &t);
    }
  }
  for (int k = 0; k < n; ++k) {
    if (var[k] >= 0) x[k] = init_detail::makePose(R[k], t[k]);
  }
  init_detail::alignToPositionPriors(graph, roots, &x);
  return x;
}

template std::vector<SE2> chordalInitialization(const PoseGraph<SE2>&);
template std::vector<SE3> chordalInitialization(const PoseGraph<SE3>&);

}  // namespace arbor
