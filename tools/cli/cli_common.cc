#include "arbor_slam/tools/cli/cli_common.h"

#include <algorithm>
#include <fstream>
#include <iostream>
#include <sstream>

namespace arbor::cli {

namespace po = boost::program_options;

AnyPoseGraph readGraphFile(const std::string& path, const ReadOptions& options,
                           ReadReport* report) {
  ReadReport own;
  ReadReport* r = report ? report : &own;
  AnyPoseGraph graph = readPoseGraphFile(path, options, r);
  const int n = static_cast<int>(r->warnings.size());
  for (int k = 0; k < std::min(n, kMaxWarningsPrinted); ++k)
    std::cerr << "warning: " << r->warnings[k] << "\n";
  if (n > kMaxWarningsPrinted)
    std::cerr << "warning: " << path << ": " << n - kMaxWarningsPrinted << " more warnings\n";
  return graph;
}

bool helpRequested(const std::vector<std::string>& args, const po::options_description& options) {
  for (const auto& a : args) {
    if (a == "--help" || a == "-h") {
      std::cout << options << "\n";
      return true;
    }
  }
  return false;
}

po::variables_map parseArguments(const std::vector<std::string>& args,
                                 const po::options_description& options,
                                 const po::positional_options_description& positional) {
  // No prefix guessing (Boost's unix_style allows it): `--thread 2` would be taken as
  // `--threads 2` today and refused as ambiguous once a flag with that prefix is added, so a
  // script that relies on a prefix breaks on a later release. Only whole names are taken.
  constexpr int kStyle =
      po::command_line_style::unix_style ^ po::command_line_style::allow_guessing;
  po::variables_map vm;
  try {
    po::store(
        po::command_line_parser(args).options(options).positional(positional).style(kStyle).run(),
        vm);
    po::notify(vm);
  } catch (const po::error& e) {
    throw UsageError(e.what());
  }
  return vm;
}

InformationPolicy parseInformationPolicy(const std::string& name) {
  if (name == "refuse") return InformationPolicy::kRefuse;
  if (name == "repair") return InformationPolicy::kRepair;
  if (name == "isotropic") return InformationPolicy::kIsotropic;
  throw UsageError("--information must be refuse, repair or isotropic, not '" + name + "'");
}

const char* toString(InformationPolicy policy) {
  switch (policy) {
    case InformationPolicy::kRefuse:
      return "refuse";
    case InformationPolicy::kRepair:
      return "repair";
    case InformationPolicy::kIsotropic:
      return "isotropic";
  }
  return "refuse";
}

double peakRssMb() {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line)) {
    if (line.rfind("VmHWM:", 0) == 0) {
      std::istringstream in(line.substr(6));
      double kb = 0;
      in >> kb;
      return kb / 1024.0;
    }
  }
  return 0.0;
}

}  // namespace arbor::cli
