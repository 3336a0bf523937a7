#include "arbor_slam/bayestree/closure_innovation.h"

#include <cmath>
#include <stdexcept>

#include <Eigen/Cholesky>

namespace arbor {
namespace {

// What AΣAᵀ (or its bound) is read as.
enum class Prediction { kOnce, kKept, kBound };

// r at the estimate and AΣAᵀ (kBound: the bound B ⪰ AΣAᵀ); false when a pose has no Σ yet.
template <class G>
bool residualAndPrediction(const IncrementalSmoother<G>& smoother, const RelativePoseEdge<G>& edge,
                           Prediction prediction, typename RelativePoseEdge<G>::Vector* r,
                           typename RelativePoseEdge<G>::Matrix* P) {
  using Matrix = typename RelativePoseEdge<G>::Matrix;
  using Vector = typename RelativePoseEdge<G>::Vector;
  using Paths = typename IncrementalSmoother<G>::PredictionPaths;
  const auto& theta = smoother.linearizationPoint();
  Matrix A_i, A_j;
  Vector r_theta;
  edge.linearize(theta[static_cast<size_t>(edge.i)], theta[static_cast<size_t>(edge.j)], &A_i, &A_j,
                 &r_theta);
  try {
    *P = prediction == Prediction::kBound
             ? smoother.predictionCovarianceBound(edge.i, A_i, edge.j, A_j)
             : smoother.predictionCovariance(
                   edge.i, A_i, edge.j, A_j,
                   prediction == Prediction::kKept ? Paths::kKept : Paths::kOnce);
  } catch (const std::logic_error&) {
    return false;  // a pose not through an update yet
  }
  *r = edge.sqrt_information_t * edge.error(smoother.estimate(edge.i), smoother.estimate(edge.j));
  return true;
}

std::optional<double> finite(double m) {
  if (!std::isfinite(m) || m < 0) return std::nullopt;
  return m;
}

template <class G>
Prediction predictionOf(typename IncrementalSmoother<G>::PredictionPaths paths) {
  return paths == IncrementalSmoother<G>::PredictionPaths::kKept ? Prediction::kKept
                                                                 : Prediction::kOnce;
}

}  // namespace

template <class G>
std::optional<double> closureInnovation(const IncrementalSmoother<G>& smoother,
                                        const RelativePoseEdge<G>& edge,
                                        typename IncrementalSmoother<G>::PredictionPaths paths) {
  using Matrix = typename RelativePoseEdge<G>::Matrix;
  typename RelativePoseEdge<G>::Vector r;
  Matrix P;
  if (!residualAndPrediction(smoother, edge, predictionOf<G>(paths), &r, &P)) return std::nullopt;
  return finite(r.dot((Matrix::Identity() + P).ldlt().solve(r)));
}

template <class G>
std::optional<double> closureInnovationLowerBound(const IncrementalSmoother<G>& smoother,
                                                  const RelativePoseEdge<G>& edge) {
  using Matrix = typename RelativePoseEdge<G>::Matrix;
  typename RelativePoseEdge<G>::Vector r;
  Matrix B;
  if (!residualAndPrediction(smoother, edge, Prediction::kBound, &r, &B)) return std::nullopt;
  return finite(r.dot((Matrix::Identity() + B).ldlt().solve(r)));
}

template <class G>
std::optional<double> leaveOneOutInnovation(
    const IncrementalSmoother<G>& smoother, const RelativePoseEdge<G>& edge,
    typename IncrementalSmoother<G>::PredictionPaths paths) {
  using Matrix = typename RelativePoseEdge<G>::Matrix;
  typename RelativePoseEdge<G>::Vector r;
  Matrix P;
  if (!residualAndPrediction(smoother, edge, predictionOf<G>(paths), &r, &P)) return std::nullopt;
  const Eigen::LLT<Matrix> llt(Matrix::Identity() - P);
  if (llt.info() != Eigen::Success) return std::nullopt;
  return finite(r.dot(llt.solve(r)));
}

template std::optional<double> closureInnovation(const IncrementalSmoother<SE2>&,
                                                 const RelativePoseEdge<SE2>&,
                                                 IncrementalSmoother<SE2>::PredictionPaths);
template std::optional<double> closureInnovation(const IncrementalSmoother<SE3>&,
                                                 const RelativePoseEdge<SE3>&,
                                                 IncrementalSmoother<SE3>::PredictionPaths);
template std::optional<double> closureInnovationLowerBound(const IncrementalSmoother<SE2>&,
                                                           const RelativePoseEdge<SE2>&);
template std::optional<double> closureInnovationLowerBound(const IncrementalSmoother<SE3>&,
                                                           const RelativePoseEdge<SE3>&);
template std::optional<double> leaveOneOutInnovation(const IncrementalSmoother<SE2>&,
                                                     const RelativePoseEdge<SE2>&,
                                                     IncrementalSmoother<SE2>::PredictionPaths);
template std::optional<double> leaveOneOutInnovation(const IncrementalSmoother<SE3>&,
                                                     const RelativePoseEdge<SE3>&,
                                                     IncrementalSmoother<SE3>::PredictionPaths);

}  // namespace arbor
