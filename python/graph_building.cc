// Graph2 / Graph3 built in memory: poses inserted in id order (dense indices stay ascending, as
// the readers make them), edges and priors validated by the library's own factories
// (RelativePoseEdge::make, PosePriorFactor::make, PositionPriorFactor::make), written with the
// library's writers and pickled as the g2o text the writer makes (shortest round-trip numbers:
// exact, but for an SE2 rotation, stored as cos/sin and written as its angle: to an ulp).
#include "graph_building.h"

#include <algorithm>
#include <optional>
#include <sstream>
#include <string>
#include <variant>

#include <pybind11/eigen.h>
#include <pybind11/stl.h>

#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/io/trajectory_writer.h"
#include "conversions.h"
#include "custom_factor_object.h"

namespace arbor::python {
namespace {

/// A pose argument: an SE2/SE3 object or its row ([x y θ] or [x y z qx qy qz qw]).
template <class G>
G poseArgument(const py::handle& h, const std::string& what) {
  if (py::isinstance<G>(h)) return h.cast<G>();
  Eigen::VectorXd row;
  try {
    row = h.cast<Eigen::VectorXd>();
  } catch (const py::cast_error&) {
    throw py::type_error(what + ": expected an " + (G::kDim == 2 ? "SE2" : "SE3") +
                         " or its row of numbers, not " +
                         std::string(py::str(py::type::of(h).attr("__name__"))));
  }
  return poseFromArray<G>(row, what);
}

template <class G>
int indexOf(const PoseGraph<G>& g, Key id, const std::string& what) {
  const auto it = g.index.find(id);
  if (it == g.index.end())
    throw std::invalid_argument(what + ": unknown pose id " + std::to_string(id) +
                                " (add_pose first)");
  return it->second;
}

/// Inserts pose `id` at its place in ascending id order, shifting the dense indices after it.
template <class G>
void insertPose(PoseGraph<G>& g, Key id, const G& x) {
  const auto at = std::lower_bound(g.ids.begin(), g.ids.end(), id);
  if (at != g.ids.end() && *at == id)
    throw std::invalid_argument("add_pose: id " + std::to_string(id) + " is already a pose");
  const int p = static_cast<int>(at - g.ids.begin());
  g.ids.insert(at, id);
  g.poses.insert(g.poses.begin() + p, x);
  const auto shift = [p](int& i) {
    if (i >= p) ++i;
  };
  for (auto& e : g.edges) {
    shift(e.i);
    shift(e.j);
  }
  for (auto& f : g.pose_priors) shift(f.i);
  for (auto& f : g.position_priors) shift(f.i);
  for (auto& f : g.custom_factors) {
    shift(f.i);
    if (f.j >= 0) shift(f.j);
  }
  for (int& f : g.fixed) shift(f);
  for (int k = p; k < g.numPoses(); ++k) g.index[g.ids[k]] = k;
}

/// Runs a factory, prefixing its std::invalid_argument with `what`.
template <class F>
auto made(const std::string& what, const F& factory) {
  try {
    return factory();
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(what + ": " + e.what());
  }
}

/// The format of write(): `format` when given (refused when the extension names another), else
/// the extension's (.g2o, .tum, .kitti), else g2o; .txt must say which (as the command line).
TrajectoryFormat formatOf(const std::string& path, const std::optional<std::string>& format) {
  const std::optional<TrajectoryFormat> by_extension = trajectoryFormatOfPath(path);
  if (!format) {
    const size_t dot = path.find_last_of('.');
    if (!by_extension && dot != std::string::npos && path.substr(dot) == ".txt")
      throw std::invalid_argument("write: " + path +
                                  ": .txt is TUM's and KITTI's extension; give format='tum' or "
                                  "'kitti'");
    return by_extension.value_or(TrajectoryFormat::kG2o);
  }
  const TrajectoryFormat named = parseTrajectoryFormat(*format);
  if (by_extension && *by_extension != named)
    throw std::invalid_argument("write: format '" + *format + "' disagrees with " + path + " (a " +
                                toString(*by_extension) + " extension)");
  return named;
}

template <class G>
py::tuple pickleState(const GraphObject<G>& o) {
  if (o.graph.numCustomFactors() > 0)
    throw std::invalid_argument("pickle: the graph holds " +
                                std::to_string(o.graph.numCustomFactors()) +
                                " custom factor(s) ('" + o.graph.custom_factors.front().name() +
                                "' first), whose Python functions are not pickled");
  std::ostringstream text;
  if (o.graph.numPoses() > 0) writeG2o(text, o.graph, o.graph.poses);
  return py::make_tuple(1, o.path, o.graph.has_initial_estimate, py::bytes(text.str()),
                        o.report.warnings, o.report.repaired, o.report.made_isotropic);
}

template <class G>
GraphObject<G> fromPickleState(const py::tuple& t) {
  if (t.size() != 7 || t[0].cast<int>() != 1)
    throw std::invalid_argument("Graph: unknown pickle state");
  GraphObject<G> o;
  o.path = t[1].cast<std::string>();
  const std::string text = t[3].cast<std::string>();
  if (!text.empty()) {
    std::istringstream in(text);
    AnyPoseGraph any = readPoseGraph(in, "<pickle>");
    auto* graph = std::get_if<PoseGraph<G>>(&any);
    if (!graph) throw std::invalid_argument("Graph: pickle of the other dimension");
    o.graph = std::move(*graph);
  }
  o.graph.has_initial_estimate = t[2].cast<bool>();
  o.report.warnings = t[4].cast<std::vector<std::string>>();
  o.report.repaired = t[5].cast<int>();
  o.report.made_isotropic = t[6].cast<int>();
  return o;
}

}  // namespace

template <class G>
void defineGraphBuilding(py::class_<GraphObject<G>>& c) {
  using Graph = GraphObject<G>;
  constexpr int k = G::kDoF;
  constexpr int d = G::kDim;
  c.def(py::init([] {
          Graph g;
          g.graph.has_initial_estimate = true;
          return g;
        }),
        "An empty graph, to fill with add_pose, add_edge and the priors.")
      .def(
          "add_pose",
          [](Graph& g, Key id, const py::object& pose) {
            insertPose(g.graph, id, poseArgument<G>(pose, "add_pose " + std::to_string(id)));
          },
          py::arg("id"), py::arg("pose"),
          "Adds pose `id` with its initial value (an SE2/SE3 or its row); ValueError if the id "
          "is a pose already.")
      .def(
          "add_edge",
          [](Graph& g, Key from, Key to, const py::object& z, const Eigen::MatrixXd& omega) {
            const std::string what =
                "add_edge " + std::to_string(from) + " -> " + std::to_string(to);
            const int i = indexOf(g.graph, from, what);
            const int j = indexOf(g.graph, to, what);
            if (i == j) throw std::invalid_argument(what + ": a self-loop");
            const G m = poseArgument<G>(z, what + ": measurement");
            const auto information = squareFromArray<k>(omega, what + ": information");
            g.graph.edges.push_back(
                made(what, [&] { return RelativePoseEdge<G>::make(i, j, m, information); }));
          },
          py::arg("from_id"), py::arg("to_id"), py::arg("measurement"), py::arg("information"),
          "Adds a relative-pose edge: the measurement (pose of to_id in the frame of from_id, an "
          "SE2/SE3 or its row) with its k×k information matrix (tangent order [translation; "
          "rotation]). ValueError for an unknown id, a self-loop or an Ω that is not symmetric "
          "positive definite.")
      .def(
          "add_pose_prior",
          [](Graph& g, Key id, const py::object& z, const Eigen::MatrixXd& omega,
             const py::object& offset) {
            const std::string what = "add_pose_prior " + std::to_string(id);
            const int i = indexOf(g.graph, id, what);
            const G m = poseArgument<G>(z, what + ": prior");
            const G o =
                offset.is_none() ? G::Identity() : poseArgument<G>(offset, what + ": offset");
            const auto information = squareFromArray<k>(omega, what + ": information");
            g.graph.pose_priors.push_back(
                made(what, [&] { return PosePriorFactor<G>::make(i, m, information, o); }));
          },
          py::arg("id"), py::arg("prior"), py::arg("information"), py::arg("offset") = py::none(),
          "Adds a prior on pose id in the world frame (on id·offset with a sensor offset) with its "
          "k×k information matrix.")
      .def(
          "add_position_prior",
          [](Graph& g, Key id, const Eigen::VectorXd& p, const Eigen::MatrixXd& omega) {
            const std::string what = "add_position_prior " + std::to_string(id);
            const int i = indexOf(g.graph, id, what);
            if (p.size() != d)
              throw std::invalid_argument(what + ": position: expected " + std::to_string(d) +
                                          " numbers, got " + std::to_string(p.size()));
            const typename G::Translation position = p;
            const auto information = squareFromArray<d>(omega, what + ": information");
            g.graph.position_priors.push_back(
                made(what, [&] { return PositionPriorFactor<G>::make(i, position, information); }));
          },
          py::arg("id"), py::arg("position"), py::arg("information"),
          "Adds a prior on the position of pose id in the world frame (d numbers, d×d "
          "information).")
      .def(
          "add_factor",
          [](Graph& g, const CustomFactorObject<G>& f) {
            std::string what =
                "add_factor '" + f.model->name() + "' on " + std::to_string(f.keys[0]);
            if (f.keys.size() == 2) what += ", " + std::to_string(f.keys[1]);
            const int i = indexOf(g.graph, f.keys[0], what);
            const int j = f.keys.size() == 2 ? indexOf(g.graph, f.keys[1], what) : -1;
            g.graph.custom_factors.push_back(made(what, [&] { return f.make(i, j); }));
          },
          py::arg("factor"),
          "Adds a factor of your own (an arbor_slam.CustomFactor2/CustomFactor3) on poses added "
          "before; ValueError for an unknown id. The batch solvers and the online smoother "
          "(add_graph) take it; write() as g2o and pickle refuse a graph holding one (ValueError).")
      .def_property_readonly(
          "num_custom_factors", [](const Graph& g) { return g.graph.numCustomFactors(); },
          "number of factors of your own (add_factor)")
      .def(
          "fix",
          [](Graph& g, Key id) {
            const int i = indexOf(g.graph, id, "fix");
            if (std::find(g.graph.fixed.begin(), g.graph.fixed.end(), i) == g.graph.fixed.end())
              g.graph.fixed.push_back(i);
          },
          py::arg("id"),
          "Holds pose id fixed in the batch solvers (g2o's FIX; without any, the gauge is "
          "chosen as for a file).")
      .def(
          "pose",
          [](const Graph& g, Key id) { return g.graph.poses[indexOf(g.graph, id, "pose")]; },
          py::arg("id"), "The initial value of pose id as an SE2/SE3.")
      .def(
          "write",
          [](const Graph& g, const std::string& path, const std::optional<std::string>& format,
             const std::optional<RowMatrix>& poses) {
            const TrajectoryFormat f = formatOf(path, format);
            const std::vector<G> values =
                poses ? posesFromArray<G>(*poses, g.graph.numPoses(), "poses") : g.graph.poses;
            writeEstimateFile(path, f, g.graph, values);
          },
          py::arg("path"), py::arg("format") = py::none(), py::arg("poses") = py::none(),
          "Writes the graph with `poses` (rows as `ids`, e.g. a SolveResult's estimate; default "
          "the graph's own) as g2o (the edges and priors too), TUM or KITTI (the poses only). "
          "format: g2o | tum | kitti, default from the extension (.g2o, .tum, .kitti; others "
          "g2o, .txt refused); a format the extension contradicts is refused. arbor_slam.FileError "
          "when the file cannot be written.")
      .def(py::pickle([](const Graph& g) { return pickleState(g); },
                      [](const py::tuple& t) { return fromPickleState<G>(t); }));
}

template void defineGraphBuilding<SE2>(py::class_<GraphObject<SE2>>& c);
template void defineGraphBuilding<SE3>(py::class_<GraphObject<SE3>>& c);

}  // namespace arbor::python
