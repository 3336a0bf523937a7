// Reading g2o (types_slam2d / types_slam3d records) and TORO (VERTEX2 / EDGE2) pose graphs.
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <optional>
#include <sstream>
#include <string_view>
#include <unordered_map>

#include "io/line_fields.h"
#include "io/pose_graph_file.h"

namespace arbor {
namespace {

using io_detail::parseId;
using io_detail::parseNumber;
using io_detail::splitFields;

enum class RecordKind { kVertex, kEdge, kFix };
enum class InfoOrder { kG2o, kToro };

struct Tag {
  std::string_view name;
  int dim;  // 0 for FIX
  RecordKind kind;
  InfoOrder order;
};

constexpr Tag kTags[] = {
    {"VERTEX_SE2", 2, RecordKind::kVertex, InfoOrder::kG2o},
    {"EDGE_SE2", 2, RecordKind::kEdge, InfoOrder::kG2o},
    {"VERTEX2", 2, RecordKind::kVertex, InfoOrder::kToro},
    {"EDGE2", 2, RecordKind::kEdge, InfoOrder::kToro},
    {"VERTEX_SE3:QUAT", 3, RecordKind::kVertex, InfoOrder::kG2o},
    {"EDGE_SE3:QUAT", 3, RecordKind::kEdge, InfoOrder::kG2o},
    {"FIX", 0, RecordKind::kFix, InfoOrder::kG2o},
};

const Tag* findTag(std::string_view name) {
  for (const Tag& tag : kTags) {
    if (tag.name == name) return &tag;
  }
  return nullptr;
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
                formatValue(v[5]) + " " + formatValue(v[6]) + ") is zero (norm " +
                formatValue(norm) + ") and cannot be normalised");
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

// Collects the records of one dimension, then resolves ids and information matrices.
template <class G>
class GraphBuilder {
 public:
  using L = Layout<G>;
  using Matrix = typename RelativePoseEdge<G>::Matrix;

  explicit GraphBuilder(std::vector<std::string>* warnings)
      : warnings_(warnings),
        g2o_order_(informationOrder<G::kDoF>(InfoOrder::kG2o)),
        toro_order_(informationOrder<G::kDoF>(InfoOrder::kToro)) {}

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
    const auto& entries = order == InfoOrder::kToro ? toro_order_ : g2o_order_;
    for (int k = 0; k < L::kInfoValues; ++k) {
      const auto [r, c] = entries[k];
      e.omega(r, c) = e.omega(c, r) = line.value(3 + L::kPoseValues + k);
    }
    if (e.from == e.to) {
      line.fail("self-loop edge " + std::to_string(e.from) + " -> " + std::to_string(e.to));
    }
    e.measurement = L::pose(v, line, warnings_);
    edges_.push_back(std::move(e));
  }

  PoseGraph<G> finish(const std::string& name, const std::vector<FixRecord>& fixes,
                      const ReadOptions& options, ReadReport* report) {
    PoseGraph<G> graph;
    graph.has_initial_estimate = !vertices_.empty();
    if (graph.has_initial_estimate) {
      for (const auto& vertex : vertices_) graph.ids.push_back(vertex.id);
    } else {
      for (const auto& e : edges_) {
        graph.ids.push_back(e.from);
        graph.ids.push_back(e.to);
      }
    }
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

    for (const auto& fix : fixes) {
      const auto it = graph.index.find(fix.id);
      if (it == graph.index.end()) {
        throw FileError(
            name + ":" + std::to_string(fix.line) + ": FIX of unknown id " +
            std::to_string(fix.id) +
            (graph.has_initial_estimate ? " (no VERTEX has it)" : " (no EDGE names it)"));
      }
      if (std::find(graph.fixed.begin(), graph.fixed.end(), it->second) != graph.fixed.end()) {
        report->warnings.push_back(name + ":" + std::to_string(fix.line) + ": id " +
                                   std::to_string(fix.id) + " is fixed more than once");
        continue;
      }
      graph.fixed.push_back(it->second);
    }

    applyInformationPolicy(name, options, report);

    graph.edges.reserve(edges_.size());
    report->edge_lines.reserve(edges_.size());
    for (std::size_t k = 0; k < edges_.size(); ++k) {
      const RawEdge& e = edges_[k];
      try {
        graph.edges.push_back(RelativePoseEdge<G>::make(endpoints[k].first, endpoints[k].second,
                                                        e.measurement, e.omega));
      } catch (const std::invalid_argument& error) {
        throw FileError(name + ":" + std::to_string(e.line) + ": " + error.what());
      }
      report->edge_lines.push_back(e.line);
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

  // Refuses, repairs or makes isotropic the information matrices, as options say.
  void applyInformationPolicy(const std::string& name, const ReadOptions& options,
                              ReadReport* report) {
    std::vector<int> bad_lines;
    for (auto& e : edges_) {
      const std::string problem = informationProblem(e.omega);
      const bool bad = !problem.empty();
      if (bad && problem.rfind("not positive definite", 0) != 0) {
        // Non-finite or asymmetric: never repaired (cannot happen for finite upper triangles).
        throw FileError(name + ":" + std::to_string(e.line) + ": information matrix " + problem);
      }
      if (bad) bad_lines.push_back(e.line);
      switch (options.information) {
        case InformationPolicy::kRefuse:
          break;
        case InformationPolicy::kRepair:
          if (bad) {
            e.omega = nearestPositiveDefinite(e.omega);
            ++report->repaired;
          }
          break;
        case InformationPolicy::kIsotropic:
          if (bad) {
            e.omega = nearestPositiveDefinite(e.omega);
            ++report->repaired;
          }
          e.omega = isotropicInformation(e.omega, G::kDim);
          ++report->made_isotropic;
          break;
      }
    }
    if (options.information != InformationPolicy::kRefuse || bad_lines.empty()) return;
    std::ostringstream os;
    os << name << ": " << bad_lines.size() << " of " << edges_.size()
       << " edges have an information matrix that is not positive definite; first at line"
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
  std::vector<RawVertex> vertices_;
  std::unordered_map<Key, int> vertex_lines_;  // id → line of its VERTEX
  std::vector<RawEdge> edges_;
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
    if (!tag) line.fail("unknown tag '" + std::string(line.tag()) + "'");

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
    if (dim == 2) {
      if (tag->kind == RecordKind::kVertex) graph2->addVertex(line);
      if (tag->kind == RecordKind::kEdge) graph2->addEdge(line, tag->order);
    } else {
      if (tag->kind == RecordKind::kVertex) graph3->addVertex(line);
      if (tag->kind == RecordKind::kEdge) graph3->addEdge(line, tag->order);
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
  std::ifstream in(path, std::ios::binary);
  if (!in) throw FileError(path + ": cannot open: " + std::strerror(errno));
  return readPoseGraph(in, path, options, report);
}

}  // namespace arbor
