// Labels of planted false loop closures (NAME.labels beside NAME.g2o, as in
// shared/datasets/robust/): one false edge a line, "i j", its two pose ids as the graph file
// writes them, in the order the edges appear. '#' starts a comment; blank lines are skipped.
// A line that is not two non-negative integer ids is a FileError naming "path:line".
#pragma once

#include <iosfwd>
#include <string>
#include <utility>
#include <vector>

#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/io/pose_graph_file.h"

namespace arbor {

using LabelPair = std::pair<Key, Key>;

/// Reads labels; `name` is used in messages in place of the path. Throws FileError.
std::vector<LabelPair> readLabels(std::istream& in, const std::string& name);
std::vector<LabelPair> readLabelsFile(const std::string& path);

/// Writes "i j" a line.
void writeLabels(std::ostream& out, const std::vector<LabelPair>& labels);
/// As writeLabels, to a file; throws FileError if it cannot be written.
void writeLabelsFile(const std::string& path, const std::vector<LabelPair>& labels);

}  // namespace arbor
