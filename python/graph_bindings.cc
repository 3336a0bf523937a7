// arbor_slam.read and the graph classes Graph2 / Graph3: a pose graph read from a g2o or TORO file,
// its poses, edges and priors as numpy arrays, and F at any poses.
#include <string>
#include <variant>

#include <pybind11/stl.h>

#include "arbor_slam/io/pose_graph_file.h"
#include "bindings.h"
#include "conversions.h"
#include "graph_building.h"
#include "graph_object.h"

namespace arbor::python {
namespace {

InformationPolicy parsePolicy(const std::string& name) {
  if (name == "refuse") return InformationPolicy::kRefuse;
  if (name == "repair") return InformationPolicy::kRepair;
  if (name == "isotropic") return InformationPolicy::kIsotropic;
  throw std::invalid_argument("information must be refuse, repair or isotropic, not '" + name +
                              "'");
}

template <class G>
void defineGraph(py::module_& m, const char* name) {
  using Graph = GraphObject<G>;
  constexpr int k = G::kDoF;
  py::class_<Graph> c(m, name,
                      (std::string("A ") + (G::kDim == 2 ? "2D" : "3D") +
                       " pose graph read from a file (arbor_slam.read) or built in memory.")
                          .c_str());
  c.def_property_readonly(
       "dimension", [](const Graph&) { return G::kDim; }, "2 or 3")
      .def_property_readonly(
          "path", [](const Graph& g) { return g.path; }, "the file read ('' in memory)")
      .def_property_readonly(
          "num_poses", [](const Graph& g) { return g.graph.numPoses(); }, "number of poses")
      .def_property_readonly(
          "num_edges", [](const Graph& g) { return g.graph.numEdges(); }, "number of edges")
      .def_property_readonly(
          "num_priors", [](const Graph& g) { return g.graph.numPriors(); },
          "number of pose and position priors")
      .def_property_readonly(
          "has_initial_estimate", [](const Graph& g) { return g.graph.has_initial_estimate; },
          "the poses are given (VERTEX lines, or add_pose), not only implied by edges")
      .def_property_readonly(
          "ids", [](const Graph& g) { return idsToArray(g.graph.ids); },
          "pose ids, ascending (the rows of poses)")
      .def_property_readonly(
          "poses", [](const Graph& g) { return posesToArray(g.graph.poses); },
          G::kDim == 2 ? "the poses (initial values), n×3 [x y θ]"
                       : "the poses (initial values), n×7 [x y z qx qy qz qw]")
      .def_property_readonly(
          "edges",
          [](const Graph& g) {
            py::array_t<std::int64_t> out({g.graph.numEdges(), 2});
            auto w = out.mutable_unchecked<2>();
            for (int e = 0; e < g.graph.numEdges(); ++e) {
              w(e, 0) = g.graph.ids[g.graph.edges[e].i];
              w(e, 1) = g.graph.ids[g.graph.edges[e].j];
            }
            return out;
          },
          "the edges' (from, to) ids, m×2, in file order")
      .def_property_readonly(
          "measurements",
          [](const Graph& g) {
            std::vector<G> z;
            for (const auto& e : g.graph.edges) z.push_back(e.measurement);
            return posesToArray(z);
          },
          "the edges' measurements (pose of `to` in the frame of `from`), one row each")
      .def_property_readonly(
          "information",
          [](const Graph& g) {
            py::array_t<double> out({g.graph.numEdges(), k, k});
            auto w = out.mutable_unchecked<3>();
            for (int e = 0; e < g.graph.numEdges(); ++e)
              for (int r = 0; r < k; ++r)
                for (int c = 0; c < k; ++c) w(e, r, c) = g.graph.edges[e].information(r, c);
            return out;
          },
          "the edges' information matrices, m×k×k")
      .def_property_readonly(
          "fixed",
          [](const Graph& g) {
            std::vector<Key> ids;
            for (int v : g.graph.gaugeIndices()) ids.push_back(g.graph.ids[v]);
            return idsToArray(ids);
          },
          "ids of the poses held fixed by the batch solvers (the gauge)")
      .def_property_readonly(
          "warnings", [](const Graph& g) { return g.report.warnings; },
          "the reader's warnings, 'path:line: ...'")
      .def_property_readonly(
          "information_repaired", [](const Graph& g) { return g.report.repaired; },
          "information matrices repaired on reading (information='repair')")
      .def_property_readonly(
          "information_isotropic", [](const Graph& g) { return g.report.made_isotropic; },
          "information matrices made isotropic on reading (information='isotropic')")
      .def(
          "objective",
          [](const Graph& g, const RowMatrix& poses) {
            return objective(g.graph, posesFromArray<G>(poses, g.graph.numPoses(), "poses"));
          },
          py::arg("poses"), "F = Σ eᵀΩe over the edges and priors at `poses` (rows as `ids`)")
      .def("__repr__", [name](const Graph& g) {
        return std::string("<arbor_slam.") + name +
               (g.path.empty() ? std::string(" (in memory)") : " '" + g.path + "'") + ": " +
               std::to_string(g.graph.numPoses()) + " poses, " +
               std::to_string(g.graph.numEdges()) + " edges, " +
               std::to_string(g.graph.numPriors()) + " priors>";
      });
  defineGraphBuilding<G>(c);
}

}  // namespace

void defineGraphs(py::module_& m) {
  defineGraph<SE2>(m, "Graph2");
  defineGraph<SE3>(m, "Graph3");
  m.def(
      "read",
      [](const std::string& path, const std::string& information) -> py::object {
        ReadOptions options;
        options.information = parsePolicy(information);
        ReadReport report;
        AnyPoseGraph any = readPoseGraphFile(path, options, &report);
        return std::visit(
            [&](auto& graph) -> py::object {
              using G = typename std::decay_t<decltype(graph)>::GroupType;
              return py::cast(GraphObject<G>{path, std::move(graph), report});
            },
            any);
      },
      py::arg("path"), py::arg("information") = "refuse",
      "Reads a g2o or TORO file (2D or 3D) into a Graph2 or Graph3. information: refuse | "
      "repair | isotropic (information matrices that are not positive definite). Raises "
      "arbor_slam.FileError naming path:line on a malformed file.");
}

}  // namespace arbor::python
