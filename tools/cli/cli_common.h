// Shared pieces of the `arbor` subcommands: argument errors, timing, reading graphs.
#pragma once

#include <chrono>
#include <stdexcept>
#include <string>
#include <vector>

#include <boost/program_options.hpp>

#include "core/information.h"

namespace arbor::cli {

/// A bad command line: printed as one line, exit code 2.
class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Parses `args` (without the subcommand name) against `options` and `positional`;
/// throws UsageError on anything unknown, missing or malformed.
boost::program_options::variables_map parseArguments(
    const std::vector<std::string>& args,
    const boost::program_options::options_description& options,
    const boost::program_options::positional_options_description& positional);

/// True (after printing `options` on stdout) when `args` holds --help or -h: the command then
/// exits 0 without parsing the rest.
bool helpRequested(const std::vector<std::string>& args,
                   const boost::program_options::options_description& options);

InformationPolicy parseInformationPolicy(const std::string& name);

class Stopwatch {
 public:
  Stopwatch() : start_(std::chrono::steady_clock::now()) {}
  double seconds() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  }

 private:
  std::chrono::steady_clock::time_point start_;
};

/// Peak resident set size of this process in MiB (from /proc/self/status), 0 if unknown.
double peakRssMb();

}  // namespace arbor::cli
