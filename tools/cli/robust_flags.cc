#include "tools/cli/robust_flags.h"

#include <cmath>
#include <stdexcept>

#include "tools/cli/cli_common.h"

namespace arbor::cli {

const char* const kKernelHelp = "with --robust: tls | gm (graduated) | cauchy | huber (reweighted)";
const char* const kInlierThresholdHelp =
    "with --robust: c² on eᵀΩe; chi2: the χ² 0.99 quantile of the edge's dimension (Ω taken at "
    "its word); auto: that quantile times the variance factor estimated over the inliers";

void readRobustFlags(const std::string& kernel, const std::string& threshold, GncOptions* gnc) {
  try {
    gnc->kernel = parseKernelKind(kernel);
  } catch (const std::invalid_argument& e) {
    throw UsageError(std::string("--kernel: ") + e.what());
  }
  if (gnc->kernel == KernelKind::kNone)
    throw UsageError("--kernel must be tls, gm, cauchy or huber with --robust, not none");
  if (threshold == "auto") {
    gnc->estimate_scale = true;
  } else if (threshold != "chi2") {
    std::size_t used = 0;
    double value = 0;
    try {
      value = std::stod(threshold, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used != threshold.size() || !(value > 0) || !std::isfinite(value))
      throw UsageError("--inlier-threshold must be chi2, auto or a number > 0, not '" + threshold +
                       "'");
    gnc->threshold = value;
  }
}

}  // namespace arbor::cli
