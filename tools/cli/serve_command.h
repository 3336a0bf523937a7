// `arbor serve`'s command line, parsed apart from starting the service (tests read the options
// it gives).
#pragma once

#include <cstdint>
#include <iostream>
#include <optional>
#include <string>
#include <vector>

#include "arbor_slam/io/trajectory_writer.h"
#include "arbor_slam/tools/cli/flag_set.h"
#include "arbor_slam/tools/cli/robust_flags.h"
#include "arbor_slam/tools/serve/serve_service.h"

namespace arbor::cli {

struct ServeCommandLine {
  std::string url;          ///< --lcm-url (empty: LCM's default)
  std::string journal_dir;  ///< --journal; options.journal_path is the file inside it
  std::string output;       ///< --output
  TrajectoryFormat format = TrajectoryFormat::kG2o;  ///< --format, or --output's extension
  bool json = false;
  bool bounded_heap = false;  ///< --bounded-heap: arbor::useBoundedHeap before serving
  RobustFlags robust;         ///< --robust ... (options.robust is set from it)
  /// --recv-buf: udpm's receive buffer request in bytes; url then carries it as recv_buf_size
  /// (replacing the URL's own). 0: kDefaultRecvBufBytes, unless the URL names its own.
  std::int64_t recv_buf_bytes = 0;
  /// --key: the deployment key file (options.bus_keys holds its keys); SIGHUP reads it again.
  std::string key_file;
  static constexpr std::int64_t kDefaultRecvBufBytes = 4 << 20;
  /// Everything the service takes (the smoother's by tools/cli/smoother_flags.h), but `log`.
  serve::ServeOptions options;
};

/// The options of `arbor serve ARGS` (under them those of --config FILE), without touching the
/// journal or LCM; nullopt after printing the help on --help or --help-all, or the options in
/// force on --print-config (to `out`). Throws UsageError on anything unknown, missing or
/// malformed, naming the flag and the value.
std::optional<ServeCommandLine> parseServeCommandLine(const std::vector<std::string>& args,
                                                      std::ostream& out = std::cout);

/// Every flag of `arbor serve`, as --help-all lists them.
std::vector<FlagInfo> serveFlags();

}  // namespace arbor::cli
