#include "arbor_slam/tools/refine/batch_solvers.h"

#include <stdexcept>

namespace arbor::refine {

const std::array<BatchSolverInfo, 4>& batchSolvers() {
  static const std::array<BatchSolverInfo, 4> table = {{
      {BatchSolver::kLevenbergMarquardt, "lm",
       "Levenberg-Marquardt (Ceres' trust-region form) from the given start", true, false, false},
      {BatchSolver::kGaussNewton, "gn", "Gauss-Newton from the given start", false, false, false},
      {BatchSolver::kDogleg, "dogleg", "Powell's dogleg from the given start", false, false, false},
      {BatchSolver::kRtr, "rtr",
       "SE-Sync's Riemannian staircase from its chordal relaxation, certificate, rounding, LM "
       "polish",
       true, true, true},
  }};
  return table;
}

const BatchSolverInfo& info(BatchSolver solver) {
  for (const BatchSolverInfo& row : batchSolvers()) {
    if (row.solver == solver) return row;
  }
  throw std::invalid_argument("BatchSolver " + std::to_string(static_cast<int>(solver)) +
                              " has no row");
}

std::string toString(BatchSolver solver) { return info(solver).name; }

std::string batchSolverNames(bool refinement_only, const std::string& separator) {
  std::string names;
  for (const BatchSolverInfo& row : batchSolvers()) {
    if (refinement_only && !row.refines) continue;
    names += (names.empty() ? "" : separator) + row.name;
  }
  return names;
}

BatchSolver parseBatchSolver(const std::string& name, const std::string& flag,
                             bool refinement_only) {
  std::vector<const char*> valid;
  for (const BatchSolverInfo& row : batchSolvers()) {
    if (refinement_only && !row.refines) continue;
    if (name == row.name) return row.solver;
    valid.push_back(row.name);
  }
  // "a, b or c"
  std::string list;
  for (size_t k = 0; k < valid.size(); ++k) {
    list += (k == 0 ? "" : k + 1 == valid.size() ? " or " : ", ") + std::string(valid[k]);
  }
  throw std::invalid_argument(flag + " must be " + list + ", not '" + name + "'");
}

std::optional<BatchMethod> batchMethod(BatchSolver solver) {
  switch (solver) {
    case BatchSolver::kLevenbergMarquardt:
      return BatchMethod::kLevenbergMarquardt;
    case BatchSolver::kGaussNewton:
      return BatchMethod::kGaussNewton;
    case BatchSolver::kDogleg:
      return BatchMethod::kDogleg;
    case BatchSolver::kRtr:
      return std::nullopt;
  }
  return std::nullopt;
}

template <class G>
BatchSolve runBatchSolver(BatchSolver solver, const PoseGraph<G>& graph, std::vector<G>* poses,
                          const BatchSolveSettings& settings) {
  BatchSolve out;
  out.solver = solver;
  if (const std::optional<BatchMethod> method = batchMethod(solver)) {
    BatchOptions options;
    options.method = *method;
    options.max_iterations = settings.max_iterations;
    options.relative_tolerance = settings.relative_tolerance;
    options.verbose = settings.verbose;
    options.cancel = settings.cancel;
    const BatchSummary s = solveBatch(graph, poses, options);
    out.F_initial = s.F_initial;
    out.F_final = s.F_final;
    out.iterations = s.iterations;
    out.time_s = s.time_s;
    out.termination = toString(s.termination);
    out.diverged = s.termination == Termination::kDiverged;
    out.cancelled = s.termination == Termination::kCancelled;
    out.message = s.message;
    out.local = s;
    return out;
  }
  RtrOptions options = settings.rtr;
  options.verbose = options.verbose || settings.verbose;
  options.cancel = settings.cancel;
  const RtrSummary s = solveRtr(graph, poses, options);
  out.F_final = s.F_final;
  out.iterations = s.rtr_iterations;
  out.time_s = s.time_s;
  out.termination =
      s.cancelled
          ? "cancelled"
          : (s.certified ? "certified"
                         : (s.relaxation_solved ? "relaxation_not_exact" : "not_certified"));
  out.cancelled = s.cancelled;
  out.message = s.message;
  out.rtr = s;
  return out;
}

template BatchSolve runBatchSolver(BatchSolver, const PoseGraph<SE2>&, std::vector<SE2>*,
                                   const BatchSolveSettings&);
template BatchSolve runBatchSolver(BatchSolver, const PoseGraph<SE3>&, std::vector<SE3>*,
                                   const BatchSolveSettings&);

}  // namespace arbor::refine
