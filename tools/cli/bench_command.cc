// arbor bench ...: runs the benchmark executable `arbor-bench` built beside `arbor`
// (kept separate so that Ceres, the baseline, is linked into the benchmark only).
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <stdexcept>

#include "arbor_slam/tools/cli/commands.h"

namespace arbor::cli {

int benchCommand(const std::vector<std::string>& args) {
  std::error_code ec;
  const auto self = std::filesystem::read_symlink("/proc/self/exe", ec);
  const std::string bench = (ec ? std::filesystem::path(".") : self.parent_path()) / "arbor-bench";
  std::vector<char*> argv;
  std::string name = "arbor-bench";
  argv.push_back(name.data());
  std::vector<std::string> copy = args;
  for (auto& a : copy) argv.push_back(a.data());
  argv.push_back(nullptr);
  execv(bench.c_str(), argv.data());
  const std::string why = std::strerror(errno);
#if ARBOR_BENCHMARKS_CONFIGURED
  // Configured with the benchmarks (the default), but only `arbor` was built (as
  // scripts/run-demo.sh does).
  const std::string how =
      "build it: cmake --build " +
      (ec ? std::string("BUILD_DIR") : self.parent_path().parent_path().string()) +
      " --target arbor-bench";
#else
  const std::string how = "configure with -DARBOR_BUILD_BENCHMARKS=ON, then build arbor-bench";
#endif
  throw std::runtime_error("cannot run " + bench + ": " + why + " (" + how + ")");
}

}  // namespace arbor::cli
