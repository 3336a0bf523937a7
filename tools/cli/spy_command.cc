// arbor spy [--lcm-url URL] [--print-command]: lcm-spy with Arbor's message types. Debian 12's
// own `lcm-spy` wrapper cannot start on its Java 17 (it passes -Xincgc, removed in Java 9),
// ignores CLASSPATH and does not put jchart2d on the class path; this runs the same main class
// (lcm.spy.Spy from liblcm-java) with lcm.jar, jchart2d.jar (libjchart2d-java) and the jar of
// Arbor's Java types (io/CMakeLists.txt: target arbor_lcm_java) on its class path.
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <stdexcept>

#include "arbor_slam/tools/cli/cli_common.h"
#include "arbor_slam/tools/cli/commands.h"

namespace arbor::cli {
namespace {

namespace fs = std::filesystem;
namespace po = boost::program_options;

/// The jar of Arbor's Java message types: $ARBOR_LCM_TYPES_JAR, else beside this executable in
/// the build tree (BUILD/io/) or in an installed prefix (PREFIX/share/arbor/).
std::string typesJar() {
  if (const char* env = std::getenv("ARBOR_LCM_TYPES_JAR")) {
    if (!fs::is_regular_file(env))
      throw std::runtime_error(std::string("ARBOR_LCM_TYPES_JAR=") + env + ": no such file");
    return env;
  }
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  const fs::path up = ec ? fs::path("..") : exe.parent_path().parent_path();
  for (const fs::path& candidate :
       {up / "io" / "arbor_lcm_types.jar", up / "share" / "arbor" / "arbor_lcm_types.jar"})
    if (fs::is_regular_file(candidate)) return candidate.string();
  throw std::runtime_error("no jar of Arbor's LCM types beside " + exe.string() +
                           " (build it: cmake --build " + up.string() +
                           " --target arbor_lcm_java; or set ARBOR_LCM_TYPES_JAR)");
}

std::string requiredJar(const std::string& path, const std::string& package) {
  if (!fs::is_regular_file(path))
    throw std::runtime_error(path + ": missing (Debian package " + package + ")");
  return path;
}

}  // namespace

int spyCommand(const std::vector<std::string>& args) {
  std::string url;
  po::options_description options("arbor spy [options] (lcm-spy with Arbor's message types)");
  options.add_options()("help,h", "show this help")(
      "lcm-url", po::value(&url), "the LCM URL to listen on (default: LCM's own, LCM_DEFAULT_URL)")(
      "print-command", "print the java command line instead of running it");
  if (helpRequested(args, options)) return 0;
  const auto vm = parseArguments(args, options, {});
  const std::string class_path = requiredJar("/usr/share/java/lcm.jar", "liblcm-java") + ":" +
                                 requiredJar("/usr/share/java/jchart2d.jar", "libjchart2d-java") +
                                 ":" + typesJar();
  std::vector<std::string> command = {"java",     "-Djava.net.preferIPv4Stack=true",
                                      "-Xmx128m", "-Xms64m",
                                      "-ea",      "-cp",
                                      class_path, "lcm.spy.Spy"};
  if (!url.empty()) command.push_back("--lcm-url=" + url);
  if (vm.count("print-command")) {
    for (size_t k = 0; k < command.size(); ++k) std::cout << (k ? " " : "") << command[k];
    std::cout << "\n";
    return 0;
  }
  std::vector<char*> argv;
  for (std::string& a : command) argv.push_back(a.data());
  argv.push_back(nullptr);
  execvp("java", argv.data());
  throw std::runtime_error(std::string("cannot run java: ") + std::strerror(errno) +
                           " (Debian package default-jre)");
}

}  // namespace arbor::cli
