// `arbor generate`'s command line, parsed apart from generating (tests read the options it
// gives).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "arbor_slam/core/information.h"
#include "arbor_slam/tools/cli/flag_set.h"
#include "arbor_slam/tools/cli/option_table.h"
#include "arbor_slam/tools/generator/false_closures.h"

namespace arbor::cli {

/// The flags of `arbor generate KIND`. A number whose default depends on KIND (--poses, --grid,
/// --closure-probability, ...) has none of its own: the kind's preset holds unless it is given.
struct GenerateOptions {
  std::string kind;  ///< manhattan | sphere | grid | vehicle | small-loop | outliers
  std::string output, truth, input, labels;
  std::uint64_t seed = 1;
  int poses = 0, rings = 0, per_ring = 0, size = 0, grid = 0, dim = 2;
  double sigma_t = 0.05, sigma_r = 0.01, closure_probability = -1, fraction = 0,
         information_scale = 1, closure_sigma_factor = 1, tail_fraction = 0, tail_factor = 1;
  sim::OutlierPolicy policy = sim::OutlierPolicy::kRandom;
  InformationPolicy information = InformationPolicy::kRefuse;
};

/// The table of `arbor generate`'s flags but -o (declared in its FlagSet: a short name).
const OptionTable<GenerateOptions>& generateOptionTable();

/// What `arbor generate ARGS` gives: the options, and which flags were given (the kinds'
/// checks ask).
struct GenerateCommandLine {
  GenerateOptions options;
  boost::program_options::variables_map given;
};

/// The options of `arbor generate ARGS`; nullopt after printing the help on --help or
/// --help-all. Throws UsageError on anything unknown, missing or malformed, naming the flag and
/// the value; the checks that depend on KIND are generateCommand's.
std::optional<GenerateCommandLine> parseGenerateCommandLine(const std::vector<std::string>& args);

/// Every flag of `arbor generate`, as --help-all lists them.
std::vector<FlagInfo> generateFlags();

}  // namespace arbor::cli
