#include "arbor_slam/io/stamps_file.h"

#include <cerrno>
#include <cstring>
#include <fstream>
#include <istream>

#include "arbor_slam/io/line_fields.h"
#include "arbor_slam/io/pose_graph_file.h"

namespace arbor {

PoseStamps readStamps(std::istream& in, const std::string& name) {
  PoseStamps stamps;
  io_detail::forEachFieldLine(
      in, name,
      [&](const std::vector<std::string_view>& fields, int /*number*/, const std::string& where) {
        if (fields.size() != 2) {
          throw FileError(where + "expected 'ID TIME_SECONDS', found " +
                          std::to_string(fields.size()) + " fields");
        }
        Key id = 0;
        if (const char* why = io_detail::parseId(fields[0], &id))
          throw FileError(where + "pose id '" + std::string(fields[0]) + "' " + why);
        double seconds = 0;
        if (const char* why = io_detail::parseNumber(fields[1], &seconds))
          throw FileError(where + "time '" + std::string(fields[1]) + "' " + why);
        if (!stamps.emplace(id, seconds).second)
          throw FileError(where + "pose id " + std::to_string(id) + " is given twice");
      });
  return stamps;
}

PoseStamps readStampsFile(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw FileError(path + ": cannot open: " + std::strerror(errno));
  return readStamps(in, path);
}

}  // namespace arbor
