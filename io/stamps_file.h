// Times of poses (a stamps file, `--stamps` of replay and batch): one pose a line, "ID TIME",
// the pose id as the graph file writes it and the time in seconds (any finite decimal, e.g.
// 1305031102.175304, the TUM RGB-D datasets' stamps). '#' starts a comment; blank lines are
// skipped. A line that is not an id and a finite number, or an id given twice, is a FileError
// naming "path:line". TUM output (io/trajectory_writer.h) writes a pose's time from it.
#pragma once

#include <iosfwd>
#include <string>
#include <unordered_map>

#include "arbor_slam/core/pose_graph.h"

namespace arbor {

/// Seconds by pose id.
using PoseStamps = std::unordered_map<Key, double>;

/// Reads stamps; `name` is used in messages in place of the path. Throws FileError.
PoseStamps readStamps(std::istream& in, const std::string& name);
PoseStamps readStampsFile(const std::string& path);

}  // namespace arbor
