// Writing an estimate as a trajectory for the usual evaluation and plotting tools (evo, the TUM
// RGB-D and KITTI benchmark scripts), beside g2o (io/pose_graph_file.h). docs/files.md gives the
// formats:
//
//   TUM    one line per pose, `timestamp tx ty tz qx qy qz qw`, the timestamp being the pose's
//          time in seconds when stamps are given (io/stamps_file.h), else the pose id;
//   KITTI  one line per pose, the 3×4 matrix [R t] row-major (r11 r12 r13 tx r21 … r33 tz).
//
// Poses are written in ascending id order. A 2D pose (x, y, θ) is the 3D pose with z = 0 and
// the rotation by θ about z (q = (0, 0, sin θ/2, cos θ/2)). Numbers are in their shortest
// exactly-round-tripping form.
#pragma once

#include <iosfwd>
#include <optional>
#include <string>
#include <vector>

#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/io/stamps_file.h"

namespace arbor {

enum class TrajectoryFormat { kG2o, kTum, kKitti };

/// "g2o", "tum", "kitti".
const char* toString(TrajectoryFormat format);
/// The format named `name` (as toString); throws std::invalid_argument naming it otherwise.
TrajectoryFormat parseTrajectoryFormat(const std::string& name);

/// The format a path's extension names: .g2o, .tum or .kitti (any case); nullopt for any other
/// extension (.txt is TUM's and KITTI's both) or none.
std::optional<TrajectoryFormat> trajectoryFormatOfPath(const std::string& path);

/// Writes poses[k] of id ids[k] (any order; written by ascending id) as TUM or KITTI; TUM's
/// timestamp is (*stamps)[id] when `stamps` is given, else the id (KITTI has no time). Throws
/// std::invalid_argument if the sizes differ, an id repeats or has no stamp, a pose is not
/// finite, or `format` is g2o (which needs the graph: writeEstimateFile).
template <class G>
void writeTrajectory(std::ostream& out, TrajectoryFormat format, const std::vector<Key>& ids,
                     const std::vector<G>& poses, const PoseStamps* stamps = nullptr);

/// An estimate of `graph` (poses in its dense order) to `path` in `format`: g2o as writeG2oFile
/// (the graph's edges and priors with the poses), TUM or KITTI as writeTrajectory over the
/// graph's ids. Throws FileError if the file cannot be written, std::invalid_argument as
/// writeTrajectory.
template <class G>
void writeEstimateFile(const std::string& path, TrajectoryFormat format, const PoseGraph<G>& graph,
                       const std::vector<G>& poses, const PoseStamps* stamps = nullptr);

}  // namespace arbor
