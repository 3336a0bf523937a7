// `arbor plot`'s command line, parsed apart from reading and drawing (tests read the options it
// gives).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "arbor_slam/tools/cli/flag_set.h"
#include "arbor_slam/tools/cli/option_table.h"

namespace arbor::cli {

struct PlotOptions {
  std::string estimate, reference;  ///< ESTIMATE [REFERENCE]
  std::string output;               ///< -o (default: ESTIMATE with .png for its extension)
  double max_time_diff = 0.01;      ///< --max-time-diff, as evo's t_max_diff
  bool json = false;
};

/// The table of `arbor plot`'s flags but -o (declared in its FlagSet: a short name).
const OptionTable<PlotOptions>& plotOptionTable();

/// The options of `arbor plot ARGS`, -o's default filled in; nullopt after printing the help on
/// --help or --help-all. Throws UsageError on anything unknown, missing or malformed.
std::optional<PlotOptions> parsePlotCommandLine(const std::vector<std::string>& args);

/// Every flag of `arbor plot`, as --help-all lists them.
std::vector<FlagInfo> plotFlags();

}  // namespace arbor::cli
