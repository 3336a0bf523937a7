// Batch nonlinear least squares on a pose graph: Gauss–Newton, Levenberg–Marquardt (Ceres'
// trust-region form) and Powell's dogleg, over the sparse Cholesky normal equations.
#pragma once

#include <string>
#include <vector>

#include "core/pose_graph.h"

namespace arbor {

enum class BatchMethod { kGaussNewton, kLevenbergMarquardt, kDogleg };
enum class Termination { kConverged, kMaxIterations, kDiverged };

std::string toString(BatchMethod method);       ///< "gn", "lm", "dogleg"
std::string toString(Termination termination);  ///< "converged", "max_iterations", "diverged"
/// Inverse of toString(BatchMethod); throws std::invalid_argument naming the value.
BatchMethod parseBatchMethod(const std::string& name);

struct BatchOptions {
  BatchMethod method = BatchMethod::kLevenbergMarquardt;
  int max_iterations = 100;
  double relative_tolerance = 1e-5;  ///< stop when (F_old − F_new)/F_old < this after a step
  bool verbose = false;              ///< per-iteration line on stderr
};

struct BatchSummary {
  double F_initial = 0, F_final = 0;
  int iterations = 0;  ///< iterations performed (accepted + rejected for LM/dogleg)
  Termination termination = Termination::kMaxIterations;
  double time_s = 0;    ///< wall time of the solve
  std::string message;  ///< e.g. why it diverged
};

/// Minimises F = objective(graph, ·) = Σ eᵀΩe over the edges, pose priors and position priors
/// (a prior on a gauge pose is a constant in F), over the poses not in graph.gaugeIndices(),
/// starting from and writing to *poses (one per graph pose). A connected component that neither
/// holds a gauge pose nor is anchored by its priors (gaugeProblem) ends as kDiverged with the
/// message naming its first pose. On divergence *poses holds the best estimate seen. Throws
/// std::invalid_argument on a size mismatch, bad indices or bad options; a singular or
/// indefinite system is reported as Termination::kDiverged with a message.
template <class G>
BatchSummary solveBatch(const PoseGraph<G>& graph, std::vector<G>* poses,
                        const BatchOptions& options = {});

/// One Gauss–Newton step from `poses` (the linearisation point), edges and priors: the tangent
/// increment per pose (zero for gauge poses). Throws std::runtime_error if the normal equations are
/// singular.
template <class G>
std::vector<typename G::Tangent> gaussNewtonStep(const PoseGraph<G>& graph,
                                                 const std::vector<G>& poses);

}  // namespace arbor
