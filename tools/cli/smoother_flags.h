// The command-line flags of SmootherOptions (bayestree/incremental_smoother.h), one binder for
// every command that runs the smoother: `arbor replay`, `arbor serve`, `arbor bench replay` and
// `arbor bench growth` take the same flags with the same help and the same checks.
#pragma once

#include <string>

#include <boost/program_options.hpp>

#include "arbor_slam/bayestree/incremental_smoother.h"
#include "arbor_slam/tools/cli/smoother_table.h"

namespace arbor::cli {

/// Adds every SmootherOptions flag to `options`, each showing its value in `defaults`:
///   --relinearize-threshold B (both β; the two below win over it), --relinearize-threshold-
///   translation B, --relinearize-threshold-rotation B, --relinearize-skip K, --wildfire A,
///   --full-backsubstitution, --no-rank-updates, --dogleg, --dogleg-radius R,
///   --dogleg-min-radius R, --finalize-rel-tol X, --finalize-max-iterations N,
///   --nested-dissection-min N, --threads N, --batch-top-share S, --reorder-decay X,
///   --relinearize inline|async, --async-min-variables N, --async-catch-up, --async-reorder,
///   --async-reorder-decay, --async-job-iterations, --async-catch-up-max-factors,
///   --cached-factor-max-ratio X.
void addSmootherFlags(boost::program_options::options_description& options,
                      const SmootherOptions& defaults = {});

/// The options those flags give in `vm` (parsed against a description addSmootherFlags filled
/// with the same `defaults`; a switch turns its option on or, for --no-rank-updates, off).
/// Throws UsageError "--FLAG must be >= 1, not 'VALUE'" on a value the smoother refuses.
SmootherOptions readSmootherFlags(const boost::program_options::variables_map& vm,
                                  const SmootherOptions& defaults = {});

/// "GN, β = 0.1, skip 10, wildfire 0.001", then whatever differs from the defaults (dogleg,
/// rank updates off, threads, …): the settings line of the benchmark tables.
std::string describeSmoother(const SmootherOptions& options);

}  // namespace arbor::cli
