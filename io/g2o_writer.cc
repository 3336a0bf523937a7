// Writing pose graphs as g2o, every number in the shortest form that reads back bit-identically.
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <ostream>

#include "io/pose_graph_file.h"

namespace arbor {
namespace {

void appendNumber(std::string* out, double v) {
  char buffer[32];
  const auto result = std::to_chars(buffer, buffer + sizeof(buffer), v);  // shortest round trip
  out->push_back(' ');
  out->append(buffer, result.ptr);
}

void appendId(std::string* out, Key id) {
  out->push_back(' ');
  out->append(std::to_string(id));
}

bool finite(const SE2& x) { return std::isfinite(x.x() + x.y() + x.cos() + x.sin()); }
bool finite(const SE3& x) {
  return x.translation().allFinite() && x.quaternion().coeffs().allFinite();
}

void appendPose(std::string* out, const SE2& x) {
  appendNumber(out, x.x());
  appendNumber(out, x.y());
  appendNumber(out, x.angle());
}

void appendPose(std::string* out, const SE3& x) {
  for (int k = 0; k < 3; ++k) appendNumber(out, x.translation()(k));
  const Eigen::Quaterniond& q = x.quaternion();
  appendNumber(out, q.x());
  appendNumber(out, q.y());
  appendNumber(out, q.z());
  appendNumber(out, q.w());
}

const char* vertexTag(const SE2&) { return "VERTEX_SE2"; }
const char* vertexTag(const SE3&) { return "VERTEX_SE3:QUAT"; }
const char* edgeTag(const SE2&) { return "EDGE_SE2"; }
const char* edgeTag(const SE3&) { return "EDGE_SE3:QUAT"; }

template <class G>
void checkWritable(const PoseGraph<G>& graph, const std::vector<G>& poses) {
  const int n = graph.numPoses();
  if (static_cast<int>(poses.size()) != n) {
    throw std::invalid_argument("writeG2o: " + std::to_string(poses.size()) +
                                " poses for a graph of " + std::to_string(n) + " ids");
  }
  for (int k = 0; k < n; ++k) {
    if (!finite(poses[k])) {
      throw std::invalid_argument("writeG2o: the pose of id " + std::to_string(graph.ids[k]) +
                                  " is not finite");
    }
  }
  for (int f : graph.fixed) {
    if (f < 0 || f >= n) {
      throw std::invalid_argument("writeG2o: fixed index " + std::to_string(f) + " out of range");
    }
  }
  for (int k = 0; k < graph.numEdges(); ++k) {
    const auto& e = graph.edges[k];
    if (e.i < 0 || e.i >= n || e.j < 0 || e.j >= n) {
      throw std::invalid_argument("writeG2o: edge " + std::to_string(k) + " (" +
                                  std::to_string(e.i) + " -> " + std::to_string(e.j) +
                                  ") has a pose index out of range");
    }
    if (!finite(e.measurement) || !e.information.allFinite()) {
      throw std::invalid_argument("writeG2o: edge " + std::to_string(k) +
                                  " has a value that is not finite");
    }
  }
}

}  // namespace

template <class G>
void writeG2o(std::ostream& out, const PoseGraph<G>& graph, const std::vector<G>& poses) {
  checkWritable(graph, poses);
  std::string text;
  text.reserve(64 * poses.size() + (24 + 24 * G::kDoF * G::kDoF) * graph.edges.size());
  for (int k = 0; k < graph.numPoses(); ++k) {
    text.append(vertexTag(poses[k]));
    appendId(&text, graph.ids[k]);
    appendPose(&text, poses[k]);
    text.push_back('\n');
  }
  for (int f : graph.fixed) {
    text.append("FIX");
    appendId(&text, graph.ids[f]);
    text.push_back('\n');
  }
  for (const auto& e : graph.edges) {
    text.append(edgeTag(e.measurement));
    appendId(&text, graph.ids[e.i]);
    appendId(&text, graph.ids[e.j]);
    appendPose(&text, e.measurement);
    for (int r = 0; r < G::kDoF; ++r) {
      for (int c = r; c < G::kDoF; ++c) appendNumber(&text, e.information(r, c));
    }
    text.push_back('\n');
  }
  out.write(text.data(), static_cast<std::streamsize>(text.size()));
}

template <class G>
void writeG2oFile(const std::string& path, const PoseGraph<G>& graph, const std::vector<G>& poses) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) throw FileError(path + ": cannot open for writing: " + std::strerror(errno));
  writeG2o(out, graph, poses);
  out.close();
  if (!out) throw FileError(path + ": write failed");
}

template void writeG2o<SE2>(std::ostream&, const PoseGraph2&, const std::vector<SE2>&);
template void writeG2o<SE3>(std::ostream&, const PoseGraph3&, const std::vector<SE3>&);
template void writeG2oFile<SE2>(const std::string&, const PoseGraph2&, const std::vector<SE2>&);
template void writeG2oFile<SE3>(const std::string&, const PoseGraph3&, const std::vector<SE3>&);

}  // namespace arbor
