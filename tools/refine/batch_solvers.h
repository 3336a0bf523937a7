// Every batch solver the tools run, in one table: `arbor batch --solver`, the background
// refinement of `arbor replay/serve --batch` (tools/refine/batch_refiner.h) and the benchmarks
// name, parse, describe and run them from here. core's BatchMethod stays core's own parameter of
// solveBatch; BatchSolver adds the certifiable solver beside it and maps onto it.
#pragma once

#include <array>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "arbor_slam/core/batch_solver.h"
#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/core/riemannian_staircase.h"

namespace arbor::refine {

enum class BatchSolver { kLevenbergMarquardt, kGaussNewton, kDogleg, kRtr };

/// One row of the table.
struct BatchSolverInfo {
  BatchSolver solver;
  const char* name;         ///< as on the command line and in reports: "lm", "gn", "dogleg", "rtr"
  const char* description;  ///< one line, for --help
  /// Can run as the periodic/background refinement (--batch of replay and serve). The
  /// refiner's keep-best pits plain LM from the incremental estimate against the chosen solver
  /// and reports F_lm (also in status_t's batch_F_lm), so the rows it runs are LM itself and
  /// RTR, whose start is its own relaxation; GN and dogleg from the incremental estimate would
  /// only repeat LM's local descent under another name.
  bool refines;
  /// Reports a certificate of global optimality (rank, λ_min, certified: SE-Sync's relaxation).
  bool certifies;
  /// Starts from its own estimate (RTR: the SE-Sync relaxation) instead of the poses it is given.
  bool own_start;
};

/// Every batch solver, one row each, in the order reports list them (LM first: the default).
const std::array<BatchSolverInfo, 4>& batchSolvers();
const BatchSolverInfo& info(BatchSolver solver);
std::string toString(BatchSolver solver);  ///< the row's name

/// The row named `name`, among the rows that refine when `refinement_only`. Throws
/// std::invalid_argument "FLAG must be lm, gn, dogleg or rtr, not 'NAME'" (the valid names from
/// the table).
BatchSolver parseBatchSolver(const std::string& name, const std::string& flag = "--solver",
                             bool refinement_only = false);
/// The valid names joined by `separator` ("lm | gn | dogleg | rtr"), for help texts.
std::string batchSolverNames(bool refinement_only = false, const std::string& separator = " | ");

/// core's method of gn, lm and dogleg; nullopt for rtr.
std::optional<BatchMethod> batchMethod(BatchSolver solver);

struct BatchSolveSettings {
  int max_iterations = 100;          ///< gn, lm, dogleg
  double relative_tolerance = 1e-5;  ///< gn, lm, dogleg: stop at a relative decrease below this
  RtrOptions rtr;                    ///< rtr
  bool verbose = false;              ///< progress on stderr
  /// Given to the solver (BatchOptions::cancel, RtrOptions::cancel; replaces rtr.cancel).
  CancellationToken cancel = {};
};

/// One run of any row, in the figures every solver has.
struct BatchSolve {
  BatchSolver solver = BatchSolver::kLevenbergMarquardt;
  /// F at the poses given (NaN for a row with own_start: it does not use them).
  double F_initial = std::numeric_limits<double>::quiet_NaN();
  double F_final = 0;
  int iterations = 0;  ///< gn/lm/dogleg: iterations; rtr: trust-region iterations
  double time_s = 0;
  /// gn/lm/dogleg: converged | max_iterations | diverged; rtr: certified | relaxation_not_exact
  /// (solved but not exact) | not_certified; either: cancelled.
  std::string termination;
  bool diverged = false;
  bool cancelled = false;  ///< stopped by settings.cancel (termination "cancelled")
  std::string message;
  std::optional<BatchSummary> local;  ///< gn, lm, dogleg: core's summary
  std::optional<RtrSummary> rtr;      ///< rtr: the staircase's summary
};

/// Runs `solver` on `graph`: gn, lm and dogleg from *poses (one per pose), rtr from its own
/// chordal relaxation (*poses only written); the estimate is left in *poses. Throws what the
/// solvers throw (std::invalid_argument on bad options or sizes).
template <class G>
BatchSolve runBatchSolver(BatchSolver solver, const PoseGraph<G>& graph, std::vector<G>* poses,
                          const BatchSolveSettings& settings = {});

}  // namespace arbor::refine
