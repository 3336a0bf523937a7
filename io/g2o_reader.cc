// Reading g2o (types_slam2d / types_slam3d records) and TORO (VERTEX2 / EDGE2) pose graphs.
//
// The priors as g2o reads them (RainerKuemmerle/g2o, g2o/types/slam2d, g2o/types/slam3d and
// g2o/core/optimizable_graph.cpp, read for this reader):
//   EDGE_PRIOR_SE2 id x y θ I(6)            EdgeSE2Prior: e = toVector(z⁻¹ x) = [t; θ]. (g2o's
//                                           tag; "EDGE_SE2_PRIOR" is only its header guard.)
//   EDGE_PRIOR_SE2_XY id x y I(3)           EdgeSE2XYPrior: e = t(x) − p, world frame.
//   PARAMS_SE3OFFSET pid x y z qx qy qz qw  ParameterSE3Offset o (quaternion normalised).
//   EDGE_SE3_PRIOR id pid x y z qx qy qz qw I(21)
//                                           EdgeSE3Prior: the vertex id, then its one parameter
//                                           id (readParamIds), then z; e = toVectorMQT(z⁻¹ n2w)
//                                           with CacheSE3Offset's n2w = x o: δ = z⁻¹ x o.
//   EDGE_SE3_XYZ_PRIOR id pid x y z I(6)    EdgeSE3XYZPrior: e = t(x) − p; its parameter must
//                                           resolve but computeError does not use the offset.
// Every I(n) is the upper triangle row by row (readInformationMatrix). g2o resolves an edge's
// parameter ids when it adds the edge and drops the edge when one is missing ("parameter 0 is
// NULL"): there is no default offset, so an EDGE_SE3_PRIOR needs its PARAMS_SE3OFFSET line even
// for id 0. We refuse such a file naming the line, and, as for VERTEX lines, accept PARAMS lines
// anywhere in the file (g2o needs them before their first use). Ω is used as written on our
// error, as for EDGE_SE3:QUAT: our rotational error is 2·vec q where g2o's is vec q
// (docs/design.md, "Objective"). POSITION_PRIOR2 / POSITION_PRIOR3 are our own position priors,
// without g2o's unused parameter id (docs/files.md).
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <string_view>
#include <unordered_map>

#include <Eigen/Cholesky>

#include "arbor_slam/io/line_fields.h"
#include "arbor_slam/io/pose_graph_file.h"

namespace arbor {
namespace {

using io_detail::parseId;
using io_detail::parseNumber;
using io_detail::splitFields;

enum class RecordKind { kVertex, kEdge, kFix, kParameter, kPosePrior, kPositionPrior };
enum class InfoOrder { kG2o, kToro };

struct Tag {
  std::string_view name;
  int dim;  // 0 for FIX
  RecordKind kind;
  InfoOrder order;
  bool has_parameter = false;    // an offset parameter id follows the pose id (g2o's 3D priors)
  const char* fields = nullptr;  // the fields after the tag, for priors and parameters
};

constexpr Tag kTags[] = {
    {"VERTEX_SE2", 2, RecordKind::kVertex, InfoOrder::kG2o},
    {"EDGE_SE2", 2, RecordKind::kEdge, InfoOrder::kG2o},
    {"VERTEX2", 2, RecordKind::kVertex, InfoOrder::kToro},
    {"EDGE2", 2, RecordKind::kEdge, InfoOrder::kToro},
    {"VERTEX_SE3:QUAT", 3, RecordKind::kVertex, InfoOrder::kG2o},
    {"EDGE_SE3:QUAT", 3, RecordKind::kEdge, InfoOrder::kG2o},
    {"FIX", 0, RecordKind::kFix, InfoOrder::kG2o},
    {"EDGE_PRIOR_SE2", 2, RecordKind::kPosePrior, InfoOrder::kG2o, false,
     "id x y theta + 6 information entries"},
    {"EDGE_PRIOR_SE2_XY", 2, RecordKind::kPositionPrior, InfoOrder::kG2o, false,
     "id x y + 3 information entries"},
    {"POSITION_PRIOR2", 2, RecordKind::kPositionPrior, InfoOrder::kG2o, false,
     "id x y + 3 information entries"},
    {"PARAMS_SE3OFFSET", 3, RecordKind::kParameter, InfoOrder::kG2o, false,
     "parameter-id x y z qx qy qz qw"},
    {"EDGE_SE3_PRIOR", 3, RecordKind::kPosePrior, InfoOrder::kG2o, true,
     "id parameter-id x y z qx qy qz qw + 21 information entries"},
    {"EDGE_SE3_XYZ_PRIOR", 3, RecordKind::kPositionPrior, InfoOrder::kG2o, true,
     "id parameter-id x y z + 6 information entries"},
    {"POSITION_PRIOR3", 3, RecordKind::kPositionPrior, InfoOrder::kG2o, false,
     "id x y z + 6 information entries"},
};

const Tag* findTag(std::string_view name) {
  for (const Tag& tag : kTags) {
    if (tag.name == name) return &tag;
  }
  return nullptr;
}

// For an unknown tag that looks like one of g2o's prior tags spelt another way: the real one.
std::string tagHint(std::string_view name) {
  static constexpr std::pair<std::string_view, std::string_view> kNearMisses[] = {
      {"EDGE_SE2_PRIOR", "EDGE_PRIOR_SE2"},        {"EDGE_SE2_XYPRIOR", "EDGE_PRIOR_SE2_XY"},
      {"EDGE_SE2_XY_PRIOR", "EDGE_PRIOR_SE2_XY"},  {"EDGE_PRIOR_SE3", "EDGE_SE3_PRIOR"},
      {"EDGE_SE3_XYZPRIOR", "EDGE_SE3_XYZ_PRIOR"}, {"EDGE_SE3_PRIOR_XYZ", "EDGE_SE3_XYZ_PRIOR"},
  };
  for (const auto& [wrong, right] : kNearMisses) {
    if (name == wrong) return " (g2o's tag is " + std::string(right) + ")";
  }
  // g2o's landmark vertices and the edges to them: variables other than poses.
  static constexpr std::string_view kLandmarkTags[] = {
      "VERTEX_XY",         "VERTEX_POINTXY",    "VERTEX_TRACKXYZ",
      "VERTEX_POINTXYZ",   "EDGE_SE2_XY",       "EDGE_SE2_POINTXY",
      "EDGE_SE3_TRACKXYZ", "EDGE_SE3_POINTXYZ", "EDGE_BEARING_SE2_XY"};
  for (std::string_view landmark : kLandmarkTags) {
    if (name == landmark)
      return " (landmarks are not supported: Arbor's variables are poses only; a measurement "
             "of a known point is a factor of your own, docs/design.md \"Factors of your own\")";
  }
  return "";
}

std::string formatValue(double v) {
  std::ostringstream os;
  os << v;
  return os.str();
}

// One line being parsed: its place for messages and its fields (fields[0] is the tag).
class Line {
 public:
  Line(const std::string& name, int number, const std::vector<std::string_view>& fields)
      : name_(name), number_(number), fields_(fields) {}

  int number() const { return number_; }
  std::string_view tag() const { return fields_[0]; }
  int size() const { return static_cast<int>(fields_.size()); }
  std::string where() const { return name_ + ":" + std::to_string(number_); }

  [[noreturn]] void fail(const std::string& message) const {
    throw FileError(where() + ": " + message);
  }

  /// Fails unless the line has exactly `count` fields after the tag, described by `layout`.
  void expectFields(int count, const char* layout) const {
    const int found = size() - 1;
    if (found == count) return;
    fail(std::string(found < count ? "too few" : "too many") + " fields for " + std::string(tag()) +
         ": expected " + std::to_string(count) + " after the tag (" + layout + "), found " +
         std::to_string(found));
  }

  double value(int k) const {
    double v = 0.0;
    if (const char* why = parseNumber(fields_[k], &v)) failField(k, why);
    return v;
  }

  Key id(int k) const {
    Key v = 0;
    if (const char* why = parseId(fields_[k], &v)) failField(k, why);
    return v;
  }

 private:
  [[noreturn]] void failField(int k, const char* why) const {
    fail("field " + std::to_string(k + 1) + " of " + std::string(tag()) + " ('" +
         std::string(fields_[k]) + "') " + why);
  }

  const std::string& name_;
  int number_;
  const std::vector<std::string_view>& fields_;
};

// x, or a failure naming the line when its translation is beyond kMaxTranslation.
template <class G>
G checkedTranslation(const G& x, const Line& line) {
  const std::string problem = translationProblem(x);
  if (!problem.empty()) line.fail(problem);
  return x;
}

// Per-group record layout: pose values after the id, information entries after the measurement.
template <class G>
struct Layout;

template <>
struct Layout<SE2> {
  static constexpr int kPoseValues = 3;
  static constexpr int kInfoValues = 6;
  static constexpr const char* kVertexFields = "id x y theta";
  static constexpr const char* kEdgeFields = "i j x y theta + 6 information entries";

  static SE2 pose(const double* v, const Line& line, std::vector<std::string>*) {
    return checkedTranslation(SE2(v[0], v[1], v[2]), line);
  }
};

template <>
struct Layout<SE3> {
  static constexpr int kPoseValues = 7;
  static constexpr int kInfoValues = 21;
  static constexpr const char* kVertexFields = "id x y z qx qy qz qw";
  static constexpr const char* kEdgeFields = "i j x y z qx qy qz qw + 21 information entries";

  static SE3 pose(const double* v, const Line& line, std::vector<std::string>* warnings) {
    const Eigen::Quaterniond q(v[6], v[3], v[4], v[5]);
    const double norm = q.norm();
    if (!(norm > 1e-12) || !std::isfinite(norm)) {
      line.fail("quaternion (qx qy qz qw) = (" + formatValue(v[3]) + " " + formatValue(v[4]) + " " +
                formatValue(v[5]) + " " + formatValue(v[6]) + ") " +
                (std::isfinite(norm) ? "is zero" : "overflows") + " (norm " + formatValue(norm) +
                ") and cannot be normalised");
    }
    if (std::abs(norm - 1.0) > 1e-3) {
      warnings->push_back(line.where() + ": quaternion norm " + formatValue(norm) +
                          " is far from 1; renormalised");
    }
    return checkedTranslation(SE3(q, Eigen::Vector3d(v[0], v[1], v[2])), line);  // normalises q
  }
};

// (row, column) of each information entry in the file's order.
template <int N>
std::vector<std::pair<int, int>> informationOrder(InfoOrder order) {
  if (N == 3 && order == InfoOrder::kToro) {
    return {{0, 0}, {0, 1}, {1, 1}, {2, 2}, {0, 2}, {1, 2}};  // I11 I12 I22 I33 I13 I23
  }
  std::vector<std::pair<int, int>> entries;  // g2o: upper triangle, row by row
  for (int r = 0; r < N; ++r) {
    for (int c = r; c < N; ++c) entries.emplace_back(r, c);
  }
  return entries;
}

struct FixRecord {
  Key id;
  int line;
};

// τ I with τ = d / tr(Ω⁻¹): the isotropic form of a position prior's d×d Ω, the precision
// isotropicInformation gives an edge's translation block (SE-Sync's τ; core/information.h).
template <int N>
Eigen::Matrix<double, N, N> isotropicPositionInformation(const Eigen::Matrix<double, N, N>& omega) {
  const Eigen::Matrix<double, N, N> covariance =
      Eigen::LLT<Eigen::Matrix<double, N, N>>(omega).solve(Eigen::Matrix<double, N, N>::Identity());
  return (N / covariance.trace()) * Eigen::Matrix<double, N, N>::Identity();
}

// Collects the records of one dimension, then resolves ids, offsets and information matrices.
template <class G>
class GraphBuilder {
 public:
  using L = Layout<G>;
  using Matrix = typename RelativePoseEdge<G>::Matrix;
  using PositionMatrix = typename PositionPriorFactor<G>::Matrix;
  using Translation = typename G::Translation;

  explicit GraphBuilder(std::vector<std::string>* warnings)
      : warnings_(warnings),
        g2o_order_(informationOrder<G::kDoF>(InfoOrder::kG2o)),
        toro_order_(informationOrder<G::kDoF>(InfoOrder::kToro)),
        position_order_(informationOrder<G::kDim>(InfoOrder::kG2o)) {}

  void addVertex(const Line& line) {
    line.expectFields(1 + L::kPoseValues, L::kVertexFields);
    const Key id = line.id(1);
    double v[L::kPoseValues];
    for (int k = 0; k < L::kPoseValues; ++k) v[k] = line.value(2 + k);
    const auto [it, inserted] = vertex_lines_.emplace(id, line.number());
    if (!inserted) {
      line.fail("duplicate VERTEX id " + std::to_string(id) + " (first at line " +
                std::to_string(it->second) + ")");
    }
    vertices_.push_back({id, L::pose(v, line, warnings_)});
  }

  void addEdge(const Line& line, InfoOrder order) {
    line.expectFields(2 + L::kPoseValues + L::kInfoValues, L::kEdgeFields);
    RawEdge e;
    e.from = line.id(1);
    e.to = line.id(2);
    e.line = line.number();
    double v[L::kPoseValues];
    for (int k = 0; k < L::kPoseValues; ++k) v[k] = line.value(3 + k);
    readInformation(line, 3 + L::kPoseValues, order == InfoOrder::kToro ? toro_order_ : g2o_order_,
                    &e.omega);
    if (e.from == e.to) {
      line.fail("self-loop edge " + std::to_string(e.from) + " -> " + std::to_string(e.to));
    }
    e.measurement = L::pose(v, line, warnings_);
    edges_.push_back(std::move(e));
  }

  /// PARAMS_SE3OFFSET pid x y z qx qy qz qw (3D only).
  void addParameter(const Line& line, const Tag& tag) {
    line.expectFields(1 + L::kPoseValues, tag.fields);
    const Key id = line.id(1);
    double v[L::kPoseValues];
    for (int k = 0; k < L::kPoseValues; ++k) v[k] = line.value(2 + k);
    const G offset = L::pose(v, line, warnings_);
    const auto [it, inserted] = parameters_.emplace(id, RawParameter{offset, line.number()});
    if (!inserted) {
      line.fail("duplicate " + std::string(tag.name) + " id " + std::to_string(id) +
                " (first at line " + std::to_string(it->second.line) + ")");
    }
  }

  void addPosePrior(const Line& line, const Tag& tag) {
    const int p = tag.has_parameter ? 1 : 0;
    line.expectFields(1 + p + L::kPoseValues + L::kInfoValues, tag.fields);
    RawPosePrior r;
    r.tag = tag.name;
    r.id = line.id(1);
    r.line = line.number();
    if (p) r.parameter = line.id(2);
    double v[L::kPoseValues];
    for (int k = 0; k < L::kPoseValues; ++k) v[k] = line.value(2 + p + k);
    readInformation(line, 2 + p + L::kPoseValues, g2o_order_, &r.omega);
    r.measurement = L::pose(v, line, warnings_);
    pose_priors_.push_back(std::move(r));
  }

  void addPositionPrior(const Line& line, const Tag& tag) {
    const int p = tag.has_parameter ? 1 : 0;
    constexpr int kInfo = G::kDim * (G::kDim + 1) / 2;
    line.expectFields(1 + p + G::kDim + kInfo, tag.fields);
    RawPositionPrior r;
    r.tag = tag.name;
    r.id = line.id(1);
    r.line = line.number();
    if (p) r.parameter = line.id(2);
    for (int k = 0; k < G::kDim; ++k) r.position(k) = line.value(2 + p + k);
    readInformation(line, 2 + p + G::kDim, position_order_, &r.omega);
    position_priors_.push_back(std::move(r));
  }

  PoseGraph<G> finish(const std::string& name, const std::vector<FixRecord>& fixes,
                      const ReadOptions& options, ReadReport* report) {
    PoseGraph<G> graph;
    graph.has_initial_estimate = !vertices_.empty();
    if (graph.has_initial_estimate) {
      for (const auto& vertex : vertices_) graph.ids.push_back(vertex.id);
    } else {  // an edges-only file: every id an edge or a prior names is a pose
      for (const auto& e : edges_) {
        graph.ids.push_back(e.from);
        graph.ids.push_back(e.to);
      }
      for (const auto& r : pose_priors_) graph.ids.push_back(r.id);
      for (const auto& r : position_priors_) graph.ids.push_back(r.id);
    }
    if (graph.ids.empty()) throw FileError(name + ": no VERTEX or EDGE records");
    std::sort(graph.ids.begin(), graph.ids.end());
    graph.ids.erase(std::unique(graph.ids.begin(), graph.ids.end()), graph.ids.end());
    graph.index.reserve(graph.ids.size());
    for (int k = 0; k < graph.numPoses(); ++k) graph.index.emplace(graph.ids[k], k);
    graph.poses.assign(graph.ids.size(), G::Identity());
    for (const auto& vertex : vertices_) graph.poses[graph.index.at(vertex.id)] = vertex.pose;

    const auto denseIndex = [&](Key id, int line, const RawEdge& e) {
      const auto it = graph.index.find(id);
      if (it == graph.index.end()) {
        throw FileError(name + ":" + std::to_string(line) + ": edge " + std::to_string(e.from) +
                        " -> " + std::to_string(e.to) + " names id " + std::to_string(id) +
                        ", which has no VERTEX");
      }
      return it->second;
    };
    std::vector<std::pair<int, int>> endpoints;
    endpoints.reserve(edges_.size());
    for (const auto& e : edges_) {
      endpoints.emplace_back(denseIndex(e.from, e.line, e), denseIndex(e.to, e.line, e));
    }
    const auto priorIndex = [&](const auto& r) {
      const auto it = graph.index.find(r.id);
      if (it == graph.index.end()) {
        throw FileError(name + ":" + std::to_string(r.line) + ": " + std::string(r.tag) +
                        " on id " + std::to_string(r.id) + ", which has no VERTEX");
      }
      return it->second;
    };
    std::vector<int> pose_prior_index, position_prior_index;
    for (const auto& r : pose_priors_) pose_prior_index.push_back(priorIndex(r));
    for (const auto& r : position_priors_) position_prior_index.push_back(priorIndex(r));
    std::vector<G> offsets;
    for (const auto& r : pose_priors_) offsets.push_back(offsetOf(name, r));
    for (const auto& r : position_priors_) {
      // g2o resolves the parameter, then computes e = t(x) − p without it; so do we.
      const G offset = offsetOf(name, r);
      if (offset.localCoordinates(G::Identity()).cwiseAbs().maxCoeff() > 0) {
        warnings_->push_back(name + ":" + std::to_string(r.line) + ": " + std::string(r.tag) +
                             "'s offset parameter " + std::to_string(*r.parameter) +
                             " is not the identity; its error t(x) − p does not use it (as in "
                             "g2o), so it is ignored");
      }
    }

    for (const auto& fix : fixes) {
      const auto it = graph.index.find(fix.id);
      if (it == graph.index.end()) {
        throw FileError(
            name + ":" + std::to_string(fix.line) + ": FIX of unknown id " +
            std::to_string(fix.id) +
            (graph.has_initial_estimate ? " (no VERTEX has it)" : " (no EDGE or prior names it)"));
      }
      if (std::find(graph.fixed.begin(), graph.fixed.end(), it->second) != graph.fixed.end()) {
        report->warnings.push_back(name + ":" + std::to_string(fix.line) + ": id " +
                                   std::to_string(fix.id) + " is fixed more than once");
        continue;
      }
      graph.fixed.push_back(it->second);
    }

    applyInformationPolicy(name, options, report);

    const auto make = [&](int line, const auto& build) {
      try {
        return build();
      } catch (const std::invalid_argument& error) {
        throw FileError(name + ":" + std::to_string(line) + ": " + error.what());
      }
    };
    graph.edges.reserve(edges_.size());
    report->edge_lines.reserve(edges_.size());
    for (std::size_t k = 0; k < edges_.size(); ++k) {
      const RawEdge& e = edges_[k];
      graph.edges.push_back(make(e.line, [&] {
        return RelativePoseEdge<G>::make(endpoints[k].first, endpoints[k].second, e.measurement,
                                         e.omega);
      }));
      report->edge_lines.push_back(e.line);
    }
    for (std::size_t k = 0; k < pose_priors_.size(); ++k) {
      const RawPosePrior& r = pose_priors_[k];
      graph.pose_priors.push_back(make(r.line, [&] {
        return PosePriorFactor<G>::make(pose_prior_index[k], r.measurement, r.omega, offsets[k]);
      }));
      report->pose_prior_lines.push_back(r.line);
    }
    for (std::size_t k = 0; k < position_priors_.size(); ++k) {
      const RawPositionPrior& r = position_priors_[k];
      graph.position_priors.push_back(make(r.line, [&] {
        return PositionPriorFactor<G>::make(position_prior_index[k], r.position, r.omega);
      }));
      report->position_prior_lines.push_back(r.line);
    }
    return graph;
  }

 private:
  struct RawVertex {
    Key id;
    G pose;
  };
  struct RawEdge {
    Key from = 0;
    Key to = 0;
    int line = 0;
    G measurement;
    Matrix omega = Matrix::Zero();
  };
  struct RawParameter {
    G offset;
    int line = 0;
  };
  struct RawPosePrior {
    std::string_view tag;
    Key id = 0;
    int line = 0;
    std::optional<Key> parameter;  // g2o's EDGE_SE3_PRIOR
    G measurement;
    Matrix omega = Matrix::Zero();
  };
  struct RawPositionPrior {
    std::string_view tag;
    Key id = 0;
    int line = 0;
    std::optional<Key> parameter;  // g2o's EDGE_SE3_XYZ_PRIOR
    Translation position = Translation::Zero();
    PositionMatrix omega = PositionMatrix::Zero();
  };

  // Fills the symmetric *omega from the line's fields from `first` on, in `entries` order.
  template <int N>
  static void readInformation(const Line& line, int first,
                              const std::vector<std::pair<int, int>>& entries,
                              Eigen::Matrix<double, N, N>* omega) {
    for (std::size_t k = 0; k < entries.size(); ++k) {
      const auto [r, c] = entries[k];
      (*omega)(r, c) = (*omega)(c, r) = line.value(first + static_cast<int>(k));
    }
  }

  // The offset a prior's parameter id names (identity for a tag without one).
  template <class Raw>
  G offsetOf(const std::string& name, const Raw& r) const {
    if (!r.parameter) return G::Identity();
    const auto it = parameters_.find(*r.parameter);
    if (it == parameters_.end()) {
      throw FileError(name + ":" + std::to_string(r.line) + ": " + std::string(r.tag) +
                      " names offset parameter " + std::to_string(*r.parameter) +
                      ", which no PARAMS_SE3OFFSET line defines (g2o has no default offset)");
    }
    return it->second.offset;
  }

  // One Ω under the policy: a non-finite, too large or asymmetric Ω is an error naming the line;
  // one that is not positive definite is refused (returns true), repaired or made isotropic.
  template <int N>
  static bool applyPolicy(Eigen::Matrix<double, N, N>* omega, int line, const std::string& name,
                          InformationPolicy policy, ReadReport* report) {
    const std::string problem = informationProblem(*omega);
    const bool bad = !problem.empty();
    if (bad && problem.rfind("not positive definite", 0) != 0) {
      // Non-finite or asymmetric: never repaired (cannot happen for finite upper triangles).
      throw FileError(name + ":" + std::to_string(line) + ": information matrix " + problem);
    }
    if (policy == InformationPolicy::kRefuse) return bad;
    if (bad) {
      *omega = nearestPositiveDefinite(*omega);
      ++report->repaired;
    }
    if (policy == InformationPolicy::kIsotropic) {
      if constexpr (N == G::kDoF) {
        *omega = isotropicInformation(*omega, G::kDim);
      } else {
        *omega = isotropicPositionInformation<N>(*omega);
      }
      ++report->made_isotropic;
    }
    return bad;
  }

  // Refuses, repairs or makes isotropic the information matrices, as options say.
  void applyInformationPolicy(const std::string& name, const ReadOptions& options,
                              ReadReport* report) {
    std::vector<int> bad_lines;
    const auto apply = [&](auto* omega, int line) {
      if (applyPolicy(omega, line, name, options.information, report)) bad_lines.push_back(line);
    };
    for (auto& e : edges_) apply(&e.omega, e.line);
    for (auto& r : pose_priors_) apply(&r.omega, r.line);
    for (auto& r : position_priors_) apply(&r.omega, r.line);
    if (options.information != InformationPolicy::kRefuse || bad_lines.empty()) return;
    std::sort(bad_lines.begin(), bad_lines.end());
    const std::size_t priors = pose_priors_.size() + position_priors_.size();
    std::ostringstream os;
    os << name << ": " << bad_lines.size() << " of " << edges_.size() + priors
       << (priors ? " edges and priors" : " edges")
       << " have an information matrix that is not positive definite; first at line"
       << (bad_lines.size() > 1 ? "s " : " ");
    constexpr std::size_t kShown = 5;
    for (std::size_t k = 0; k < std::min(kShown, bad_lines.size()); ++k) {
      os << (k ? ", " : "") << bad_lines[k];
    }
    if (bad_lines.size() > kShown) os << ", …";
    os << "; use --information repair or isotropic";
    throw FileError(os.str());
  }

  std::vector<std::string>* warnings_;
  std::vector<std::pair<int, int>> g2o_order_;
  std::vector<std::pair<int, int>> toro_order_;
  std::vector<std::pair<int, int>> position_order_;  // g2o's upper triangle of the kDim×kDim Ω
  std::vector<RawVertex> vertices_;
  std::unordered_map<Key, int> vertex_lines_;  // id → line of its VERTEX
  std::vector<RawEdge> edges_;
  std::unordered_map<Key, RawParameter> parameters_;  // PARAMS_SE3OFFSET id → offset
  std::vector<RawPosePrior> pose_priors_;
  std::vector<RawPositionPrior> position_priors_;
};

AnyPoseGraph parsePoseGraph(std::string_view text, const std::string& name,
                            const ReadOptions& options, ReadReport* report) {
  ReadReport local;
  ReadReport& out = report ? *report : local;
  out = ReadReport{};

  std::optional<GraphBuilder<SE2>> graph2;
  std::optional<GraphBuilder<SE3>> graph3;
  int dim = 0;
  int dim_line = 0;
  std::string dim_tag;
  std::vector<FixRecord> fixes;
  std::vector<std::string_view> fields;
  int line_number = 0;
  std::size_t pos = 0;
  while (pos < text.size()) {
    std::size_t end = text.find('\n', pos);
    if (end == std::string_view::npos) end = text.size();
    const std::string_view text_line = text.substr(pos, end - pos);
    pos = end + 1;
    ++line_number;
    splitFields(text_line, &fields);
    if (fields.empty()) continue;
    const Line line(name, line_number, fields);
    const Tag* tag = findTag(line.tag());
    if (!tag) line.fail("unknown tag '" + std::string(line.tag()) + "'" + tagHint(line.tag()));

    if (tag->kind == RecordKind::kFix) {
      if (line.size() < 2) line.fail("too few fields for FIX: expected at least one id");
      for (int k = 1; k < line.size(); ++k) fixes.push_back({line.id(k), line_number});
      continue;
    }
    if (dim == 0) {
      dim = tag->dim;
      dim_line = line_number;
      dim_tag = std::string(tag->name);
      if (dim == 2) graph2.emplace(&out.warnings);
      if (dim == 3) graph3.emplace(&out.warnings);
    } else if (tag->dim != dim) {
      line.fail("mixes 2D and 3D records: " + std::string(tag->name) + " after " + dim_tag +
                " at line " + std::to_string(dim_line));
    }
    const auto add = [&](auto& graph) {
      switch (tag->kind) {
        case RecordKind::kVertex:
          return graph.addVertex(line);
        case RecordKind::kEdge:
          return graph.addEdge(line, tag->order);
        case RecordKind::kParameter:
          return graph.addParameter(line, *tag);
        case RecordKind::kPosePrior:
          return graph.addPosePrior(line, *tag);
        case RecordKind::kPositionPrior:
          return graph.addPositionPrior(line, *tag);
        case RecordKind::kFix:
          return;  // handled above
      }
    };
    if (dim == 2) {
      add(*graph2);
    } else {
      add(*graph3);
    }
  }
  if (dim == 0) throw FileError(name + ": no VERTEX or EDGE records");
  if (dim == 2) return graph2->finish(name, fixes, options, &out);
  return graph3->finish(name, fixes, options, &out);
}

}  // namespace

AnyPoseGraph readPoseGraph(std::istream& in, const std::string& name, const ReadOptions& options,
                           ReadReport* report) {
  std::ostringstream buffer;
  buffer << in.rdbuf();  // an empty stream sets failbit on buffer only
  if (in.bad()) throw FileError(name + ": read error");
  return parsePoseGraph(buffer.str(), name, options, report);
}

AnyPoseGraph readPoseGraphFile(const std::string& path, const ReadOptions& options,
                               ReadReport* report) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec))
    throw FileError(path + ": is a directory, not a g2o or TORO file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw FileError(path + ": cannot open: " + std::strerror(errno));
  return readPoseGraph(in, path, options, report);
}

}  // namespace arbor
