// The parts of the module `arbor_slam` (docs/python.md), each defined in its own file and called by
// arbor_module.cc in this order (later parts use the classes of earlier ones).
#pragma once

#include <string>

#include <pybind11/pybind11.h>

#include "arbor_slam/bayestree/online_gnc.h"
#include "arbor_slam/core/robust_kernel.h"

namespace arbor::python {

/// The robust options of `solve` and the online smoother (docs/python.md, "Robust"): the
/// command line's robust flags (--kernel, --inlier-threshold with chi2/auto, and replay's online
/// flags) as one object.
struct RobustSettings {
  KernelKind kernel = KernelKind::kTruncatedLeastSquares;
  /// c² on eᵀΩe when > 0; ≤ 0: the χ² quantile of the edge's dimension at `confidence`.
  double threshold = 0.0;
  double confidence = 0.99;
  /// Batch only: scale the χ² quantile by the estimated variance factor ("auto").
  bool estimate_scale = false;
  /// The online smoother only: its own options, as `arbor replay`'s online robust flags set
  /// them (kernel, threshold and confidence above are copied over these; solve() refuses any
  /// that differs from RobustOptions' default).
  RobustOptions online;
};

void definePoses(pybind11::module_& m);          ///< SE2, SE3
void defineCustomFactors(pybind11::module_& m);  ///< CustomFactor2, CustomFactor3
void defineGraphs(pybind11::module_& m);         ///< Graph2, Graph3, read()
void defineSolve(pybind11::module_& m);          ///< RobustOptions, SolveResult, solve()
/// UpdateStats, OnlineStats, AddGraphResult, Closure, RefineResult
void defineSmootherResults(pybind11::module_& m);
void defineSmoother(pybind11::module_& m);  ///< OnlineSmoother2, OnlineSmoother3

}  // namespace arbor::python
