// The table of SmootherOptions' options (tools/cli/option_table.h): each flag of the smoother,
// its tier, default, range and help, in the order the flags apply (--relinearize-threshold, which
// sets both thresholds, before the two specific ones). The command line (smoother_flags.h) binds
// it; nothing here depends on a command-line library.
#pragma once

#include "arbor_slam/bayestree/incremental_smoother.h"
#include "arbor_slam/tools/cli/option_table.h"

namespace arbor::cli {

const OptionTable<SmootherOptions>& smootherOptionTable();

}  // namespace arbor::cli
