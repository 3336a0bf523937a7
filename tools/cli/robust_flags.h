// The robust options `arbor batch --robust` and `arbor bench robust` share: --kernel and
// --inlier-threshold, read into GncOptions (core/gnc_solver.h).
#pragma once

#include <string>

#include "core/gnc_solver.h"

namespace arbor::cli {

/// Help texts of the two flags.
extern const char* const kKernelHelp;
extern const char* const kInlierThresholdHelp;

/// --kernel tls | gm | cauchy | huber (not none) into gnc->kernel; --inlier-threshold chi2 (the
/// χ² quantile, Ω taken at its word) | auto (that quantile × the variance factor:
/// gnc->estimate_scale) | a number > 0 (gnc->threshold). Throws UsageError naming the flag and
/// the value.
void readRobustFlags(const std::string& kernel, const std::string& threshold, GncOptions* gnc);

}  // namespace arbor::cli
