// The directory a test process writes its files in: under the system's temp directory, named
// for the process (arbor_test_PID), made on first use and removed with everything in it when
// that process exits. Tests leave nothing behind even when an assertion ends them early or a
// component writes files beside the one the test names (a journal's `.reserve`). A child that
// forks from the process and exits does not remove it: only the process that made it does.
#pragma once

#include <unistd.h>

#include <filesystem>
#include <string>
#include <system_error>

namespace arbor::testing {

inline const std::filesystem::path& processTempDir() {
  struct Dir {
    pid_t owner = ::getpid();
    std::filesystem::path path =
        std::filesystem::temp_directory_path() / ("arbor_test_" + std::to_string(::getpid()));
    Dir() { std::filesystem::create_directories(path); }
    ~Dir() {
      std::error_code ignored;
      if (::getpid() == owner) std::filesystem::remove_all(path, ignored);
    }
  };
  static const Dir dir;
  return dir.path;
}

}  // namespace arbor::testing
