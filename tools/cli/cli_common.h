// Shared pieces of the `arbor` subcommands: argument errors, timing, reading graphs.
#pragma once

#include <chrono>
#include <stdexcept>
#include <string>
#include <vector>

#include <boost/program_options.hpp>
#include <nlohmann/json.hpp>

#include "arbor_slam/core/information.h"
#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/tools/cli/option_table.h"

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
/// "refuse", "repair" or "isotropic".
const char* toString(InformationPolicy policy);

/// A table's --information refuse|repair|isotropic at `access(o)`, an InformationPolicy.
template <class O, class Access>
OptionSpec<O> informationOption(Tier tier, std::string section, Access access) {
  return wordOption<O>(
      "information", tier, std::move(section), "refuse|repair|isotropic",
      "what to do with information matrices that are not positive definite", access,
      [](const std::string& text) {
        if (text == "refuse") return InformationPolicy::kRefuse;
        if (text == "repair") return InformationPolicy::kRepair;
        if (text == "isotropic") return InformationPolicy::kIsotropic;
        throw std::invalid_argument("must be refuse, repair or isotropic, not '" + text + "'");
      },
      [](InformationPolicy p) { return toString(p); });
}

/// readPoseGraphFile (io/pose_graph_file.h), then the reader's warnings (a renormalised
/// quaternion, say) on stderr, "warning: path:line: …" one a line: the first
/// kMaxWarningsPrinted, then how many more.
AnyPoseGraph readGraphFile(const std::string& path, const ReadOptions& options,
                           ReadReport* report = nullptr);
inline constexpr int kMaxWarningsPrinted = 20;

/// The keys every command's --json shares about its input: file, nodes, edges, dim.
template <class G>
nlohmann::json graphJson(const std::string& file, const PoseGraph<G>& graph) {
  return {
      {"file", file}, {"nodes", graph.numPoses()}, {"edges", graph.numEdges()}, {"dim", G::kDim}};
}

/// "FILE (2D, N poses, M edges)": the first line of every command's text summary.
template <class G>
std::string graphLine(const std::string& file, const PoseGraph<G>& graph) {
  return file + " (" + std::to_string(G::kDim) + "D, " + std::to_string(graph.numPoses()) +
         " poses, " + std::to_string(graph.numEdges()) + " edges)";
}

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
