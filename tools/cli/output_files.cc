#include "arbor_slam/tools/cli/output_files.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <variant>
#include <vector>

#include "arbor_slam/tools/cli/cli_common.h"

namespace arbor::cli {

TrajectoryFormat outputFormat(const std::string& output, const std::string& format) {
  const std::optional<TrajectoryFormat> by_extension = trajectoryFormatOfPath(output);
  if (format.empty()) {
    const size_t dot = output.find_last_of('.');
    if (!by_extension && dot != std::string::npos && output.substr(dot) == ".txt")
      throw UsageError("-o " + output +
                       ": .txt is TUM's and KITTI's extension; say --format tum or kitti");
    return by_extension.value_or(TrajectoryFormat::kG2o);
  }
  TrajectoryFormat named;
  try {
    named = parseTrajectoryFormat(format);
  } catch (const std::invalid_argument& e) {
    throw UsageError(std::string("--format: ") + e.what());
  }
  if (by_extension && *by_extension != named)
    throw UsageError("--format " + format + " disagrees with -o " + output + " (a " +
                     toString(*by_extension) + " extension)");
  return named;
}

void requireTumForStamps(const std::string& stamps_file, TrajectoryFormat format) {
  if (!stamps_file.empty() && format != TrajectoryFormat::kTum)
    throw UsageError("--stamps " + stamps_file + " needs TUM output (-o FILE.tum or --format tum)");
}

PoseStamps readStampsOf(const std::string& stamps_file, const AnyPoseGraph& graph) {
  PoseStamps stamps = readStampsFile(stamps_file);
  std::visit(
      [&](const auto& g) {
        std::vector<Key> ids = g.ids;
        std::sort(ids.begin(), ids.end());
        for (Key id : ids)
          if (!stamps.count(id))
            throw FileError(stamps_file + ": no time for pose id " + std::to_string(id) +
                            " (every pose of the graph needs one)");
      },
      graph);
  return stamps;
}

void requireWritable(const std::string& flag, const std::string& path) {
  if (path.empty()) return;
  struct stat before {};
  const bool existed = ::stat(path.c_str(), &before) == 0;
  if (existed && S_ISDIR(before.st_mode))
    throw UsageError(flag + " " + path + ": cannot write: " + std::strerror(EISDIR));
  if (existed && !S_ISREG(before.st_mode)) {
    // A device or a FIFO: opening one may block (a FIFO without a reader) or have effects.
    if (::access(path.c_str(), W_OK) != 0)
      throw UsageError(flag + " " + path + ": cannot write: " + std::strerror(errno));
    return;
  }
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_CLOEXEC, 0666);
  if (fd < 0) throw UsageError(flag + " " + path + ": cannot write: " + std::strerror(errno));
  ::close(fd);
  if (!existed) ::unlink(path.c_str());
}

}  // namespace arbor::cli
