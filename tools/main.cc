// arbor: an incremental pose-graph smoother. `arbor help` lists the subcommands.
#include <cstdlib>
#include <iostream>
#include <map>
#include <string>
#include <vector>

#include "arbor_slam/core/blas_threads.h"
#include "arbor_slam/tools/cli/cli_common.h"
#include "arbor_slam/tools/cli/commands.h"

namespace {

using Command = int (*)(const std::vector<std::string>&);

const std::map<std::string, std::pair<Command, const char*>>& commands() {
  static const std::map<std::string, std::pair<Command, const char*>> table = {
      {"batch", {arbor::cli::batchCommand, "solve a g2o/TORO file in batch (GN, LM, dogleg)"}},
      {"bench",
       {arbor::cli::benchCommand, "benchmarks on the shared datasets (arbor bench --help)"}},
      {"replay",
       {arbor::cli::replayCommand, "feed a file edge by edge to the incremental smoother"}},
      {"generate",
       {arbor::cli::generateCommand,
        "write a synthetic pose graph (manhattan, sphere, grid) or add false loop closures "
        "to one (outliers)"}},
      {"serve",
       {arbor::cli::serveCommand, "run the smoother as an LCM service (edges in, estimates out)"}},
      {"publish", {arbor::cli::publishCommand, "stream a file's edges over LCM to arbor serve"}},
      {"plot",
       {arbor::cli::plotCommand,
        "draw an estimate as a PNG; with a reference, its ATE and RPE (evo's definitions)"}},
      {"keygen",
       {arbor::cli::keygenCommand, "write a new deployment key for an authenticated bus (--key)"}},
      {"spy", {arbor::cli::spyCommand, "lcm-spy with Arbor's message types (a GUI)"}},
      {"command",
       {arbor::cli::commandCommand,
        "take an edge back from arbor serve, or give it back (disable|enable FROM TO), or ask it "
        "for covariances (covariance ID [ID2])"}},
  };
  return table;
}

void printUsage(std::ostream& out) {
  out << "usage: arbor <command> [options]   (arbor <command> --help for its options)\n"
         "       arbor --version\n";
  for (const auto& [name, entry] : commands()) out << "  " << name << "\t" << entry.second << "\n";
  out << "exit codes: 0 done, 1 error (unreadable or malformed input, a failed run), 2 bad "
         "arguments, 3 a batch solve that diverged\n";
}

}  // namespace

int main(int argc, char** argv) {
  arbor::useOneBlasThread();  // first thing: stops OpenBLAS's idle workers early
  if (argc >= 2 && std::string(argv[1]) == "--version") {
    std::cout << "arbor " << ARBOR_VERSION << "\n";
    return 0;
  }
  if (argc < 2 || std::string(argv[1]) == "help" || std::string(argv[1]) == "--help" ||
      std::string(argv[1]) == "-h") {
    printUsage(argc < 2 ? std::cerr : std::cout);
    return argc < 2 ? 2 : 0;
  }
  const std::string name = argv[1];
  const auto it = commands().find(name);
  if (it == commands().end()) {
    std::cerr << "arbor: unknown command '" << name << "' (try arbor help)\n";
    return 2;
  }
  const std::vector<std::string> args(argv + 2, argv + argc);
  try {
    return it->second.first(args);
  } catch (const arbor::cli::UsageError& e) {
    std::cerr << "arbor " << name << ": " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "arbor " << name << ": error: " << e.what() << "\n";
    return 1;
  }
}
