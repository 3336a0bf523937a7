// Writing pose graphs as g2o, every number in the shortest form that reads back bit-identically;
// priors as g2o's prior tags (io/g2o_reader.cc gives their fields and meaning).
#include <array>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <optional>
#include <ostream>
#include <type_traits>

#include "arbor_slam/core/finite_pose.h"
#include "arbor_slam/io/pose_graph_file.h"

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

template <class Vector>
void appendVector(std::string* out, const Vector& v) {
  for (int k = 0; k < v.size(); ++k) appendNumber(out, v(k));
}

// The upper triangle of Ω row by row (g2o's readInformationMatrix order).
template <class Matrix>
void appendInformation(std::string* out, const Matrix& omega) {
  for (int r = 0; r < omega.rows(); ++r) {
    for (int c = r; c < omega.cols(); ++c) appendNumber(out, omega(r, c));
  }
}

const char* vertexTag(const SE2&) { return "VERTEX_SE2"; }
const char* vertexTag(const SE3&) { return "VERTEX_SE3:QUAT"; }
const char* edgeTag(const SE2&) { return "EDGE_SE2"; }
const char* edgeTag(const SE3&) { return "EDGE_SE3:QUAT"; }
const char* posePriorTag(const SE2&) { return "EDGE_PRIOR_SE2"; }
const char* posePriorTag(const SE3&) { return "EDGE_SE3_PRIOR"; }
const char* positionPriorTag(const SE2&) { return "EDGE_PRIOR_SE2_XY"; }
const char* positionPriorTag(const SE3&) { return "EDGE_SE3_XYZ_PRIOR"; }

// g2o's 3D priors name a PARAMS_SE3OFFSET; 2D ones have none (EdgeSE2Prior has no offset).
template <class G>
constexpr bool kPriorsNameAnOffset = std::is_same_v<G, SE3>;

// The PARAMS_SE3OFFSET ids of a 3D graph's priors: 0 is the identity (every position prior and
// every pose prior without an offset names it), then each distinct offset in order of first use.
class OffsetTable {
 public:
  explicit OffsetTable(const std::vector<PosePriorFactor<SE3>>& priors) {
    offsets_.push_back(SE3::Identity());
    for (const auto& p : priors) ids_.push_back(p.has_offset ? idOf(p.offset) : 0);
  }
  const std::vector<SE3>& offsets() const { return offsets_; }
  Key idOfPrior(std::size_t k) const { return ids_[k]; }

 private:
  using Coefficients = std::array<double, 7>;
  Key idOf(const SE3& offset) {
    const Coefficients c = {offset.translation().x(), offset.translation().y(),
                            offset.translation().z(), offset.quaternion().x(),
                            offset.quaternion().y(),  offset.quaternion().z(),
                            offset.quaternion().w()};
    const auto [it, inserted] = index_.emplace(c, static_cast<Key>(offsets_.size()));
    if (inserted) offsets_.push_back(offset);
    return it->second;
  }
  std::vector<SE3> offsets_;
  std::map<Coefficients, Key> index_;
  std::vector<Key> ids_;
};

template <class G>
void checkWritable(const PoseGraph<G>& graph, const std::vector<G>& poses) {
  const int n = graph.numPoses();
  if (!graph.custom_factors.empty()) {
    throw std::invalid_argument("writeG2o: custom factor 0 ('" +
                                graph.custom_factors.front().name() + "', of " +
                                std::to_string(graph.custom_factors.size()) +
                                ") has no g2o tag; g2o holds relative poses and priors only");
  }
  if (static_cast<int>(poses.size()) != n) {
    throw std::invalid_argument("writeG2o: " + std::to_string(poses.size()) +
                                " poses for a graph of " + std::to_string(n) + " ids");
  }
  for (int k = 0; k < n; ++k) {
    if (!allFinite(poses[k])) {
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
    if (!allFinite(e.measurement) || !e.information.allFinite()) {
      throw std::invalid_argument("writeG2o: edge " + std::to_string(k) +
                                  " has a value that is not finite");
    }
  }
  const auto checkPrior = [n](const char* what, std::size_t k, int i, bool finite_values) {
    if (i < 0 || i >= n) {
      throw std::invalid_argument("writeG2o: " + std::string(what) + " " + std::to_string(k) +
                                  " has the pose index " + std::to_string(i) + ", out of range");
    }
    if (!finite_values) {
      throw std::invalid_argument("writeG2o: " + std::string(what) + " " + std::to_string(k) +
                                  " has a value that is not finite");
    }
  };
  for (std::size_t k = 0; k < graph.pose_priors.size(); ++k) {
    const auto& p = graph.pose_priors[k];
    checkPrior("pose prior", k, p.i,
               allFinite(p.measurement) && allFinite(p.offset) && p.information.allFinite());
    if (!kPriorsNameAnOffset<G> && p.has_offset) {
      throw std::invalid_argument("writeG2o: pose prior " + std::to_string(k) +
                                  " has an offset, which g2o's EDGE_PRIOR_SE2 cannot hold");
    }
  }
  for (std::size_t k = 0; k < graph.position_priors.size(); ++k) {
    const auto& p = graph.position_priors[k];
    checkPrior("position prior", k, p.i, p.position.allFinite() && p.information.allFinite());
  }
}

// The prior lines (after the edges) and, for 3D, the PARAMS_SE3OFFSET lines they name.
template <class G>
void appendPriors(std::string* params, std::string* text, const PoseGraph<G>& graph) {
  if (!graph.hasPriors()) return;
  std::optional<OffsetTable> offsets;
  if constexpr (kPriorsNameAnOffset<G>) {
    offsets.emplace(graph.pose_priors);
    for (std::size_t k = 0; k < offsets->offsets().size(); ++k) {
      params->append("PARAMS_SE3OFFSET");
      appendId(params, static_cast<Key>(k));
      appendPose(params, offsets->offsets()[k]);
      params->push_back('\n');
    }
  }
  for (std::size_t k = 0; k < graph.pose_priors.size(); ++k) {
    const auto& p = graph.pose_priors[k];
    text->append(posePriorTag(p.measurement));
    appendId(text, graph.ids[p.i]);
    if (offsets) appendId(text, offsets->idOfPrior(k));
    appendPose(text, p.measurement);
    appendInformation(text, p.information);
    text->push_back('\n');
  }
  for (const auto& p : graph.position_priors) {
    text->append(positionPriorTag(G()));
    appendId(text, graph.ids[p.i]);
    if (offsets) appendId(text, 0);  // the identity: g2o's error t(x) − p does not use it
    appendVector(text, p.position);
    appendInformation(text, p.information);
    text->push_back('\n');
  }
}

}  // namespace

template <class G>
void writeG2o(std::ostream& out, const PoseGraph<G>& graph, const std::vector<G>& poses) {
  checkWritable(graph, poses);
  std::string text, priors;
  text.reserve(64 * poses.size() + (24 + 24 * G::kDoF * G::kDoF) * graph.edges.size());
  appendPriors(&text, &priors, graph);  // PARAMS_SE3OFFSET lines first, as g2o writes them
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
    appendInformation(&text, e.information);
    text.push_back('\n');
  }
  text.append(priors);
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
