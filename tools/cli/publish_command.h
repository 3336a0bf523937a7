// `arbor publish`'s command line, parsed apart from reading the file and opening the bus (tests
// read the options it gives).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/tools/cli/bus_key_flag.h"
#include "arbor_slam/tools/cli/flag_set.h"
#include "arbor_slam/tools/cli/option_table.h"

namespace arbor::cli {

struct PublishOptions {
  std::string file;
  BusClientOptions bus;  ///< --lcm-url, --channel-prefix, --key (busClientOptionTable())
  double rate = 0;       ///< --rate: edges per second; 0: a burst
  bool burst = false;    ///< --burst (the default; excludes --rate)
  std::int64_t sender = 1;
  long skip = 0, count = -1;
  bool wait = false, wait_ready = false, json = false;
  double timeout_s = 60;
  ReadOptions read;          ///< --information
  std::string edge_choices;  ///< --edge-choices FILE (io/edge_choice_file.h)
  long resend_window = 0;    ///< --resend-window N (0: off)
};

/// The table of `arbor publish`'s own flags (the bus's are busClientOptionTable()).
const OptionTable<PublishOptions>& publishOptionTable();

/// The options of `arbor publish ARGS`; nullopt after printing the help on --help or --help-all.
/// Throws UsageError on anything unknown, missing or malformed, naming the flag and the value.
std::optional<PublishOptions> parsePublishCommandLine(const std::vector<std::string>& args);

/// Every flag of `arbor publish`, as --help-all lists them.
std::vector<FlagInfo> publishFlags();

}  // namespace arbor::cli
