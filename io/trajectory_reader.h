// Reading an estimate back for evaluation (`arbor plot`): a TUM or KITTI trajectory as
// io/trajectory_writer.h writes it (docs/files.md), or a g2o/TORO file's poses (its VERTEX lines).
// Every pose is 3D: a 2D pose (x, y, θ) is at z = 0, rotated by θ about z.
#pragma once

#include <iosfwd>
#include <string>
#include <vector>

#include "arbor_slam/core/se3.h"

namespace arbor {

/// Poses with their times: TUM's timestamps, a graph file's pose ids, KITTI's line numbers
/// (0, 1, …).
struct Trajectory {
  std::vector<double> stamps;
  std::vector<SE3> poses;
};

/// TUM (`timestamp tx ty tz qx qy qz qw`) or KITTI (`r11 r12 r13 tx … r33 tz`) text, told apart
/// by the first line's field count (8 or 12); '#' starts a comment, blank lines are skipped. A
/// line of another count than the first's, a field that is not a finite number, a zero
/// quaternion or a KITTI rotation that is not one (‖RᵀR − I‖ > 1e-6) is a FileError naming
/// "name:line". TUM's quaternion is normalised.
Trajectory readTrajectory(std::istream& in, const std::string& name);

/// readTrajectory of `path`; a file whose first field is a word (VERTEX_SE2, EDGE3, …) is read
/// as a pose graph (readPoseGraphFile) and gives its poses by ascending id, stamped with the
/// ids; one without VERTEX lines (no estimate) is a FileError.
Trajectory readTrajectoryFile(const std::string& path);

}  // namespace arbor
