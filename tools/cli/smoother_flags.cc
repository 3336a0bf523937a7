#include "arbor_slam/tools/cli/smoother_flags.h"

#include <cmath>
#include <sstream>

#include "arbor_slam/tools/cli/cli_common.h"
#include "arbor_slam/tools/cli/flag_set.h"

namespace arbor::cli {

void addSmootherFlags(boost::program_options::options_description& options,
                      const SmootherOptions& defaults) {
  addOptions(smootherOptionTable(), options, defaults);
}

SmootherOptions readSmootherFlags(const boost::program_options::variables_map& vm,
                                  const SmootherOptions& defaults) {
  SmootherOptions o = defaults;
  readOptions(smootherOptionTable(), vm, &o);
  if (o.relinearize == RelinearizationMode::kAsync && o.dogleg)
    throw UsageError("--relinearize async needs Gauss-Newton: drop --dogleg");
  if (o.solve_budget_mb > 0 && (o.dogleg || o.full_backsubstitution))
    throw UsageError(
        "--solve-budget-mb needs Gauss-Newton and partial back-substitution: drop --dogleg and "
        "--full-backsubstitution");
  return o;
}

std::string describeSmoother(const SmootherOptions& o) {
  const SmootherOptions d;
  std::ostringstream out;
  out << (o.dogleg ? "dogleg" : "GN") << ", β = ";
  if (o.relinearize_threshold_translation == o.relinearize_threshold_rotation) {
    out << o.relinearize_threshold_translation;
  } else {
    out << o.relinearize_threshold_translation << " (translation) / "
        << o.relinearize_threshold_rotation << " (rotation)";
  }
  out << ", skip " << o.relinearize_skip << ", wildfire " << o.wildfire_threshold;
  if (o.dogleg && (o.dogleg_initial_radius != d.dogleg_initial_radius ||
                   o.dogleg_min_radius != d.dogleg_min_radius)) {
    out << ", radius " << o.dogleg_initial_radius << " (min " << o.dogleg_min_radius << ")";
  }
  if (o.full_backsubstitution) out << ", full back-substitution";
  if (o.solve_budget_mb > 0) out << ", solve budget " << o.solve_budget_mb << " MB";
  if (!o.rank_updates) out << ", no rank updates";
  if (!o.newest_last) out << ", no newest-last";
  if (o.nested_dissection_min != d.nested_dissection_min)
    out << ", nested dissection from " << o.nested_dissection_min << " variables";
  if (o.threads != d.threads) out << ", " << o.threads << " thread(s)";
  if (o.batch.top_share != d.batch.top_share)
    out << ", batch past a top share of " << o.batch.top_share;
  if (o.batch.reorder_decay != d.batch.reorder_decay)
    out << ", re-order at decay " << o.batch.reorder_decay;
  if (o.cached_factors.max_ratio != d.cached_factors.max_ratio)
    out << ", cached factors up to " << o.cached_factors.max_ratio << "x the conditional";
  if (o.relinearize == RelinearizationMode::kAsync) {
    out << ", async relinearisation";
    if (o.async.min_variables != d.async.min_variables)
      out << " from " << o.async.min_variables << " variables";
    if (o.async.catch_up != d.async.catch_up) out << ", catch-up on the swap";
    if (o.async.reorder_in_background != d.async.reorder_in_background)
      out << ", re-ordering inline";
    else if (o.async.reorder_decay != d.async.reorder_decay)
      out << ", re-ordering job at decay " << o.async.reorder_decay;
    if (o.async.job_iterations != d.async.job_iterations)
      out << ", " << o.async.job_iterations << " Gauss-Newton iterations a job";
  }
  if (o.finalize_relative_tolerance != d.finalize_relative_tolerance ||
      o.finalize_max_iterations != d.finalize_max_iterations) {
    out << ", final pass to " << o.finalize_relative_tolerance << " in at most "
        << o.finalize_max_iterations << " iterations";
  }
  return out.str();
}

}  // namespace arbor::cli
