// What the commands write (-o, --covariances, --rejected-out, --latency-csv): the estimate's
// format, taken from --format or the output's extension, and a check that each path can be
// written, made before the graph is read or solved.
#pragma once

#include <string>

#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/io/stamps_file.h"
#include "arbor_slam/io/trajectory_writer.h"

namespace arbor::cli {

/// The format of the estimate written to `output`: `format` (--format; "" when not given) or
/// else the extension's (.g2o, .tum, .kitti), else g2o. Throws UsageError on an unknown format
/// name, on a --format that the extension contradicts (naming both), and on a .txt output
/// without --format (TUM and KITTI both use .txt).
TrajectoryFormat outputFormat(const std::string& output, const std::string& format);

/// The help of --format and --stamps (replay, batch, serve's --format).
inline constexpr const char* kOutputFormatHelp =
    "of -o: g2o (the graph with the estimate) | tum (`time tx ty tz qx qy qz qw` a line) | kitti "
    "(3x4 [R t] row-major a line), by ascending id; default: -o's extension (.g2o, .tum, .kitti; "
    ".txt needs --format), else g2o; docs/files.md";
inline constexpr const char* kStampsHelp =
    "with TUM output: the poses' times, `ID TIME_SECONDS` a line (docs/files.md); without it "
    "TUM's time is the pose id";

/// Throws UsageError when `stamps_file` is given and `format` is not TUM.
void requireTumForStamps(const std::string& stamps_file, TrajectoryFormat format);

/// The stamps of `stamps_file` (readStampsFile), checked to hold every pose of `graph`: throws
/// FileError naming the file and the first pose id (ascending) without a time.
PoseStamps readStampsOf(const std::string& stamps_file, const AnyPoseGraph& graph);

/// Throws UsageError "FLAG PATH: cannot write: REASON" (REASON the OS's) unless PATH can be
/// opened for writing. An existing file is left as it is; a file that did not exist is removed
/// again; a device or FIFO is checked with access(W_OK), not opened. Nothing to check when PATH
/// is empty (the flag not given).
void requireWritable(const std::string& flag, const std::string& path);

}  // namespace arbor::cli
