#include "arbor_slam/io/labels_file.h"

#include <cerrno>
#include <cstring>
#include <fstream>
#include <istream>
#include <ostream>

#include "arbor_slam/io/line_fields.h"

namespace arbor {

std::vector<LabelPair> readLabels(std::istream& in, const std::string& name) {
  std::vector<LabelPair> labels;
  io_detail::forEachFieldLine(
      in, name,
      [&](const std::vector<std::string_view>& fields, int /*number*/, const std::string& where) {
        if (fields.size() != 2) {
          throw FileError(where + "expected two pose ids 'i j', found " +
                          std::to_string(fields.size()) + " fields");
        }
        Key ids[2];
        for (int k = 0; k < 2; ++k) {
          if (const char* why = io_detail::parseId(fields[k], &ids[k])) {
            throw FileError(where + "pose id '" + std::string(fields[k]) + "' " + why);
          }
        }
        labels.emplace_back(ids[0], ids[1]);
      });
  return labels;
}

std::vector<LabelPair> readLabelsFile(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw FileError(path + ": cannot open: " + std::strerror(errno));
  return readLabels(in, path);
}

void writeLabels(std::ostream& out, const std::vector<LabelPair>& labels) {
  for (const auto& [i, j] : labels) out << i << ' ' << j << '\n';
}

void writeLabelsFile(const std::string& path, const std::vector<LabelPair>& labels) {
  std::ofstream out(path);
  if (!out) throw FileError(path + ": cannot open for writing: " + std::strerror(errno));
  writeLabels(out, labels);
  out.flush();
  if (!out) throw FileError(path + ": write failed: " + std::strerror(errno));
}

}  // namespace arbor
