// The online robust layer's options as data (tools/cli/option_table.h), the one place they are
// listed: the command line (robust_flags.h) and Python's arbor.RobustOptions keywords (the names
// with '_' for '-') read them. Nothing here depends on a command-line library.
#pragma once

#include "arbor_slam/bayestree/online_gnc.h"
#include "arbor_slam/tools/cli/option_table.h"

namespace arbor::cli {

/// The --help section of every robust flag.
extern const char* const kRobustSection;

/// The table of the online smoother's own robust flags (`arbor replay`, `arbor serve`; every
/// row needs --robust): --entry innovation|residual, --noise-scale estimated|given,
/// --corroboration-window K, --finalize-rounds N and --rules-off RULE,... (bayestree/
/// robust_options.h). Each flag is its field's name with '-' for '_'.
const OptionTable<RobustOptions>& onlineRobustOptionTable();

}  // namespace arbor::cli
