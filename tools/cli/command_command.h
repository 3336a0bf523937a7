// `arbor command`'s command lines, parsed apart from opening the bus (tests read the options
// they give): disable|enable FROM TO (edge_command_command.cc) and covariance ID [ID2]
// (covariance_command.cc).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/tools/cli/bus_key_flag.h"
#include "arbor_slam/tools/cli/flag_set.h"
#include "arbor_slam/tools/cli/option_table.h"

namespace arbor::cli {

/// `arbor command disable|enable FROM TO`.
struct EdgeCommandOptions {
  std::string kind;  ///< disable or enable
  Key from = 0, to = 0;
  BusClientOptions bus;  ///< --lcm-url, --channel-prefix, --key (busClientOptionTable())
  std::int64_t sender = 1;
  std::int64_t seq = 0;  ///< --seq; 0: not given (milliseconds since the epoch are taken)
  bool wait = false, json = false;
  double timeout_s = 10;
};

/// The table of its own flags (the bus's are busClientOptionTable()).
const OptionTable<EdgeCommandOptions>& edgeCommandOptionTable();

/// The options of `arbor command disable|enable FROM TO ARGS` (`args` after "command"); nullopt
/// after printing the help on --help or --help-all. Throws UsageError on anything unknown,
/// missing or malformed. A missing --seq stays 0.
std::optional<EdgeCommandOptions> parseEdgeCommandLine(const std::vector<std::string>& args);

/// Every flag of `arbor command disable|enable`, as --help-all lists them.
std::vector<FlagInfo> edgeCommandFlags();

/// `arbor command covariance ID [ID2]`.
struct CovarianceCommandOptions {
  std::vector<Key> ids;  ///< one (a marginal) or two (a joint)
  BusClientOptions bus;
  bool json = false;
  double timeout_s = 10;
};

const OptionTable<CovarianceCommandOptions>& covarianceCommandOptionTable();

/// The options of `arbor command covariance ARGS` (`args` after "covariance"), as
/// parseEdgeCommandLine.
std::optional<CovarianceCommandOptions> parseCovarianceCommandLine(
    const std::vector<std::string>& args);

/// Every flag of `arbor command covariance`, as --help-all lists them.
std::vector<FlagInfo> covarianceCommandFlags();

}  // namespace arbor::cli
