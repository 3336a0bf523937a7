// The command-line flags of robustness against false loop closures, one binder for every
// command that has them (`arbor batch`, `arbor replay`, `arbor serve`): --robust, --kernel,
// --inlier-threshold, --rejected-out, with the same help and the same checks.
#pragma once

#include <string>

#include <boost/program_options.hpp>

#include "arbor_slam/bayestree/incremental_smoother.h"
#include "arbor_slam/bayestree/online_gnc.h"
#include "arbor_slam/core/gnc_solver.h"
#include "arbor_slam/core/robust_kernel.h"
#include "arbor_slam/tools/cli/online_robust_table.h"

namespace arbor::cli {

class FlagSet;

struct RobustFlags {
  bool robust = false;                                     ///< --robust
  KernelKind kernel = KernelKind::kTruncatedLeastSquares;  ///< --kernel tls|gm|cauchy|huber
  /// --inlier-threshold: c² on eᵀΩe when > 0; 0 with `estimate_scale` false: "chi2" (the χ²
  /// 0.99 quantile of the edge's dimension); "auto" sets estimate_scale.
  double threshold = 0.0;
  bool estimate_scale = false;
  /// "online" (batch only): c² from a robust online replay of the graph (cli/online_threshold.h).
  bool online_threshold = false;
  std::string rejected_out;  ///< --rejected-out FILE: the rejected edges, `i j` a line
};

/// Adds the four flags to `flags` (tools/cli/flag_set.h), under kRobustSection: --robust,
/// --kernel and --inlier-threshold common, --rejected-out advanced. `robust_help` says what
/// --robust does in this command, `default_threshold` is --inlier-threshold's default ("online"
/// for `arbor batch`).
void addRobustFlags(FlagSet& flags, const std::string& robust_help,
                    const std::string& default_threshold = "chi2");

/// The flags in `vm` (parsed against a description addRobustFlags filled). Throws UsageError
/// on a bad kernel or threshold, on `auto` when `allow_auto` is false, and on --kernel,
/// --inlier-threshold or --rejected-out given without --robust.
RobustFlags readRobustFlags(const boost::program_options::variables_map& vm, bool allow_auto);

/// Those flags into `robust`. Throws UsageError on a bad value, and when one is given without
/// --robust (`robust_on` false).
void readOnlineRobustFlags(const boost::program_options::variables_map& vm, bool robust_on,
                           RobustOptions* robust);

/// Help texts of --kernel and --inlier-threshold (for a command that reads them itself).
extern const char* const kKernelHelp;
extern const char* const kInlierThresholdHelp;

/// --kernel and --inlier-threshold given as strings (`arbor bench robust`) into gnc's kernel,
/// threshold and estimate_scale, with readRobustFlags' checks (auto allowed; online, which
/// needs the graph, refused).
void readRobustFlags(const std::string& kernel, const std::string& threshold, GncOptions* gnc);

/// --robust with --relinearize async is refused (UsageError): the online robust layer judges each
/// loop closure against an estimate that, with async, lags the background job, and its replays
/// end wrecked (docs/design.md, "Online robust smoothing").
void requireInlineWithRobust(bool robust_on, const SmootherOptions& smoother);

}  // namespace arbor::cli
