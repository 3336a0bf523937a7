#include "arbor_slam/io/trajectory_reader.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <istream>
#include <numeric>
#include <variant>

#include <Eigen/Geometry>

#include "arbor_slam/io/line_fields.h"
#include "arbor_slam/io/pose_graph_file.h"

namespace arbor {
namespace {

SE3 spatial(const SE2& x) {
  return SE3(Eigen::Quaterniond(Eigen::AngleAxisd(x.angle(), Eigen::Vector3d::UnitZ())),
             Eigen::Vector3d(x.x(), x.y(), 0.0));
}
SE3 spatial(const SE3& x) { return x; }

// The first field of the first line that has one, or "".
std::string firstField(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw FileError(path + ": cannot open: " + std::strerror(errno));
  std::vector<std::string_view> fields;
  std::string line;
  while (std::getline(in, line)) {
    io_detail::splitFields(line, &fields);
    if (!fields.empty()) return std::string(fields[0]);
  }
  return "";
}

}  // namespace

Trajectory readTrajectory(std::istream& in, const std::string& name) {
  Trajectory t;
  size_t count = 0;
  double v[12];
  io_detail::forEachFieldLine(
      in, name,
      [&](const std::vector<std::string_view>& fields, int /*number*/, const std::string& where) {
        if (count == 0) {
          if (fields.size() != 8 && fields.size() != 12)
            throw FileError(where + "expected 8 fields (TUM) or 12 (KITTI), found " +
                            std::to_string(fields.size()));
          count = fields.size();
        } else if (fields.size() != count) {
          throw FileError(where + "expected " + std::to_string(count) +
                          " fields as the first line, " + "found " + std::to_string(fields.size()));
        }
        for (size_t k = 0; k < count; ++k)
          if (const char* why = io_detail::parseNumber(fields[k], &v[k]))
            throw FileError(where + "field " + std::to_string(k + 1) + " '" +
                            std::string(fields[k]) + "' " + why);
        if (count == 8) {
          Eigen::Quaterniond q(v[7], v[4], v[5], v[6]);
          if (!(q.norm() > 0)) throw FileError(where + "the quaternion is zero");
          t.stamps.push_back(v[0]);
          t.poses.emplace_back(q.normalized(), Eigen::Vector3d(v[1], v[2], v[3]));
        } else {
          Eigen::Matrix3d R;
          R << v[0], v[1], v[2], v[4], v[5], v[6], v[8], v[9], v[10];
          if ((R.transpose() * R - Eigen::Matrix3d::Identity()).norm() > 1e-6 ||
              R.determinant() < 0)
            throw FileError(where + "the 3x3 part is not a rotation");
          t.stamps.push_back(static_cast<double>(t.poses.size()));
          t.poses.emplace_back(Eigen::Quaterniond(R).normalized(),
                               Eigen::Vector3d(v[3], v[7], v[11]));
        }
      });
  return t;
}

Trajectory readTrajectoryFile(const std::string& path) {
  const std::string first = firstField(path);
  if (!first.empty() && std::isalpha(static_cast<unsigned char>(first[0]))) {
    const AnyPoseGraph any = readPoseGraphFile(path);
    return std::visit(
        [&](const auto& graph) {
          if (!graph.has_initial_estimate)
            throw FileError(path + ": no VERTEX lines, so no estimate to read");
          std::vector<size_t> order(graph.ids.size());
          std::iota(order.begin(), order.end(), size_t{0});
          std::sort(order.begin(), order.end(),
                    [&](size_t a, size_t b) { return graph.ids[a] < graph.ids[b]; });
          Trajectory t;
          for (size_t k : order) {
            t.stamps.push_back(static_cast<double>(graph.ids[k]));
            t.poses.push_back(spatial(graph.poses[k]));
          }
          return t;
        },
        any);
  }
  std::ifstream in(path);
  if (!in) throw FileError(path + ": cannot open: " + std::strerror(errno));
  return readTrajectory(in, path);
}

}  // namespace arbor
