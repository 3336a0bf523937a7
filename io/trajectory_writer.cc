#include "arbor_slam/io/trajectory_writer.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <numeric>
#include <ostream>
#include <stdexcept>

#include <Eigen/Geometry>

#include "arbor_slam/io/pose_graph_file.h"

namespace arbor {
namespace {

void appendNumber(std::string* out, double v) {
  char buffer[32];
  const auto result = std::to_chars(buffer, buffer + sizeof(buffer), v);  // shortest round trip
  if (!out->empty() && out->back() != '\n') out->push_back(' ');
  out->append(buffer, result.ptr);
}

// The pose as a 3D rotation and translation: 2D poses with z = 0, rotated by θ about z.
void toSpatial(const SE2& x, Eigen::Quaterniond* q, Eigen::Vector3d* t) {
  const double half = 0.5 * x.angle();
  *q = Eigen::Quaterniond(std::cos(half), 0.0, 0.0, std::sin(half));
  *t = Eigen::Vector3d(x.x(), x.y(), 0.0);
}
void toSpatial(const SE3& x, Eigen::Quaterniond* q, Eigen::Vector3d* t) {
  *q = x.quaternion();
  *t = x.translation();
}

}  // namespace

const char* toString(TrajectoryFormat format) {
  switch (format) {
    case TrajectoryFormat::kG2o:
      return "g2o";
    case TrajectoryFormat::kTum:
      return "tum";
    case TrajectoryFormat::kKitti:
      return "kitti";
  }
  return "?";
}

TrajectoryFormat parseTrajectoryFormat(const std::string& name) {
  for (TrajectoryFormat f :
       {TrajectoryFormat::kG2o, TrajectoryFormat::kTum, TrajectoryFormat::kKitti})
    if (name == toString(f)) return f;
  throw std::invalid_argument("unknown trajectory format '" + name + "' (g2o, tum or kitti)");
}

std::optional<TrajectoryFormat> trajectoryFormatOfPath(const std::string& path) {
  const size_t slash = path.find_last_of('/');
  const size_t dot = path.find_last_of('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return std::nullopt;
  std::string extension = path.substr(dot + 1);
  for (char& c : extension) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  for (TrajectoryFormat f :
       {TrajectoryFormat::kG2o, TrajectoryFormat::kTum, TrajectoryFormat::kKitti})
    if (extension == toString(f)) return f;
  return std::nullopt;
}

template <class G>
void writeTrajectory(std::ostream& out, TrajectoryFormat format, const std::vector<Key>& ids,
                     const std::vector<G>& poses, const PoseStamps* stamps) {
  if (format == TrajectoryFormat::kG2o)
    throw std::invalid_argument("writeTrajectory: g2o needs the graph (writeEstimateFile)");
  if (ids.size() != poses.size())
    throw std::invalid_argument("writeTrajectory: " + std::to_string(ids.size()) + " ids for " +
                                std::to_string(poses.size()) + " poses");
  std::vector<size_t> order(ids.size());
  std::iota(order.begin(), order.end(), size_t{0});
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return ids[a] < ids[b]; });
  std::string text;
  for (size_t k = 0; k < order.size(); ++k) {
    const Key id = ids[order[k]];
    if (k > 0 && ids[order[k - 1]] == id)
      throw std::invalid_argument("writeTrajectory: pose id " + std::to_string(id) + " repeats");
    Eigen::Quaterniond q;
    Eigen::Vector3d t;
    toSpatial(poses[order[k]], &q, &t);
    if (!t.allFinite() || !q.coeffs().allFinite())
      throw std::invalid_argument("writeTrajectory: pose id " + std::to_string(id) +
                                  " is not finite");
    if (format == TrajectoryFormat::kTum) {
      if (stamps == nullptr) {
        text += std::to_string(id);
      } else {
        const auto stamp = stamps->find(id);
        if (stamp == stamps->end())
          throw std::invalid_argument("writeTrajectory: pose id " + std::to_string(id) +
                                      " has no stamp");
        appendNumber(&text, stamp->second);
      }
      for (int r = 0; r < 3; ++r) appendNumber(&text, t(r));
      for (double c : {q.x(), q.y(), q.z(), q.w()}) appendNumber(&text, c);
    } else {
      const Eigen::Matrix3d R = q.normalized().toRotationMatrix();
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) appendNumber(&text, R(r, c));
        appendNumber(&text, t(r));
      }
    }
    text.push_back('\n');
  }
  out << text;
}

template <class G>
void writeEstimateFile(const std::string& path, TrajectoryFormat format, const PoseGraph<G>& graph,
                       const std::vector<G>& poses, const PoseStamps* stamps) {
  if (format == TrajectoryFormat::kG2o) return writeG2oFile(path, graph, poses);
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) throw FileError(path + ": cannot open for writing: " + std::strerror(errno));
  writeTrajectory(out, format, graph.ids, poses, stamps);
  out.close();
  if (!out) throw FileError(path + ": write failed");
}

template void writeTrajectory<SE2>(std::ostream&, TrajectoryFormat, const std::vector<Key>&,
                                   const std::vector<SE2>&, const PoseStamps*);
template void writeTrajectory<SE3>(std::ostream&, TrajectoryFormat, const std::vector<Key>&,
                                   const std::vector<SE3>&, const PoseStamps*);
template void writeEstimateFile<SE2>(const std::string&, TrajectoryFormat, const PoseGraph2&,
                                     const std::vector<SE2>&, const PoseStamps*);
template void writeEstimateFile<SE3>(const std::string&, TrajectoryFormat, const PoseGraph3&,
                                     const std::vector<SE3>&, const PoseStamps*);

}  // namespace arbor
