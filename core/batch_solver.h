// Batch nonlinear least squares on a pose graph: Gauss–Newton, Levenberg–Marquardt (Ceres'
// trust-region form) and Powell's dogleg, over the sparse Cholesky normal equations.
#pragma once

#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "arbor_slam/core/cancellation.h"
#include "arbor_slam/core/pose_graph.h"

namespace arbor {

enum class BatchMethod { kGaussNewton, kLevenbergMarquardt, kDogleg };
enum class Termination { kConverged, kMaxIterations, kDiverged, kCancelled };

std::string toString(BatchMethod method);       ///< "gn", "lm", "dogleg"
std::string toString(Termination termination);  ///< "converged", "max_iterations", "diverged",
                                                ///< "cancelled"
/// Inverse of toString(BatchMethod); throws std::invalid_argument naming the value.
BatchMethod parseBatchMethod(const std::string& name);

struct BatchOptions {
  BatchMethod method = BatchMethod::kLevenbergMarquardt;
  int max_iterations = 100;
  double relative_tolerance = 1e-5;  ///< stop when (F_old − F_new)/F_old < this after a step
  bool verbose = false;              ///< per-iteration line on stderr
  /// Checked before each iteration: once cancelled the solve stops with Termination::kCancelled
  /// and *poses holds the best estimate so far (F_final ≤ F_initial).
  CancellationToken cancel = {};
};

/// BatchOptions with the given method, iteration limit and tolerance (the rest default).
inline BatchOptions batchOptions(BatchMethod method, int max_iterations,
                                 double relative_tolerance) {
  BatchOptions o;
  o.method = method;
  o.max_iterations = max_iterations;
  o.relative_tolerance = relative_tolerance;
  return o;
}

struct BatchSummary {
  double F_initial = 0, F_final = 0;
  int iterations = 0;  ///< iterations performed (accepted + rejected for LM/dogleg)
  Termination termination = Termination::kMaxIterations;
  double time_s = 0;    ///< wall time of the solve
  std::string message;  ///< e.g. why it diverged
};

/// Minimises F = objective(graph, ·) = Σ eᵀΩe over the edges, priors and custom factors (a
/// unary term on a gauge pose is a constant in F), over the poses not in graph.gaugeIndices(),
/// starting from and writing to *poses (one per graph pose). A connected component that neither
/// holds a gauge pose nor is anchored by its priors (gaugeProblem) ends as kDiverged with the
/// message naming its first pose. On divergence *poses holds the best estimate seen. Throws
/// std::invalid_argument on a size mismatch, bad indices or bad options; a singular or
/// indefinite system is reported as Termination::kDiverged with a message.
template <class G>
BatchSummary solveBatch(const PoseGraph<G>& graph, std::vector<G>* poses,
                        const BatchOptions& options = {});

/// Σ w_k e_kᵀΩ_k e_k over the edges (one weight per edge, in edge order) plus the priors' and
/// the custom factors' Σ eᵀΩe: the objective of the weighted (IRLS) problem. Throws
/// std::invalid_argument on a size mismatch.
template <class G>
double weightedObjective(const PoseGraph<G>& graph, const std::vector<double>& edge_weights,
                         const std::vector<G>& poses) {
  if (edge_weights.size() != graph.edges.size())
    throw std::invalid_argument("weightedObjective: " + std::to_string(edge_weights.size()) +
                                " weights for " + std::to_string(graph.edges.size()) + " edges");
  double f = 0.0;
  for (size_t k = 0; k < graph.edges.size(); ++k) {
    if (edge_weights[k] == 0.0) continue;
    const auto& e = graph.edges[k];
    f += edge_weights[k] * e.cost(poses[e.i], poses[e.j]);
  }
  for (const auto& p : graph.pose_priors) f += p.cost(poses[p.i]);
  for (const auto& p : graph.position_priors) f += p.cost(poses[p.i]);
  for (const auto& c : graph.custom_factors) f += c.cost(poses);
  return f;
}

template <class G>
class NormalEquations;

/// solveBatch on the weighted objective weightedObjective(graph, w, ·) (edge k's whitened A and
/// r scaled by √w_k: one iteratively reweighted least-squares solve), for a solver that solves
/// the same graph many times with new weights (core/gnc_solver.h): the ordering and symbolic
/// factorisation are computed once, here. A weight of 0 keeps the edge's place in the pattern
/// and removes its terms. The graph must outlive this object.
template <class G>
class WeightedBatchSolver {
 public:
  explicit WeightedBatchSolver(const PoseGraph<G>& graph);
  ~WeightedBatchSolver();
  WeightedBatchSolver(const WeightedBatchSolver&) = delete;
  WeightedBatchSolver& operator=(const WeightedBatchSolver&) = delete;

  /// As solveBatch, with F the weighted objective (F_initial, F_final in the summary are it).
  /// Throws std::invalid_argument on a weight that is negative or not finite, or a size
  /// mismatch.
  BatchSummary solve(const std::vector<double>& edge_weights, std::vector<G>* poses,
                     const BatchOptions& options = {});

 private:
  const PoseGraph<G>& graph_;
  std::unique_ptr<NormalEquations<G>> equations_;
};

/// One Gauss–Newton step from `poses` (the linearisation point), edges and priors: the tangent
/// increment per pose (zero for gauge poses). Throws std::runtime_error if the normal equations are
/// singular.
template <class G>
std::vector<typename G::Tangent> gaussNewtonStep(const PoseGraph<G>& graph,
                                                 const std::vector<G>& poses);

}  // namespace arbor
