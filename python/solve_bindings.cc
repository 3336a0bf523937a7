// arbor_slam.solve: a batch solve of a Graph2 / Graph3 with any row of the solver table
// (tools/refine/batch_solvers.h: lm, gn, dogleg, rtr) from any initialisation, optionally
// robust (GNC, as `arbor batch --robust`), and arbor_slam.RobustOptions.
#include <algorithm>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <pybind11/stl.h>

#include "arbor_slam/core/gnc_solver.h"
#include "arbor_slam/core/initialization.h"
#include "arbor_slam/tools/cli/online_robust_table.h"
#include "arbor_slam/tools/refine/batch_solvers.h"
#include "bindings.h"
#include "conversions.h"
#include "graph_object.h"
#include "option_keywords.h"
#include "record.h"

namespace arbor::python {
namespace {

using cli::onlineRobustOptionTable;
using cli::OptionSpec;
using refine::BatchSolver;

/// What solve() returns (arbor_slam.SolveResult).
struct SolveOutcome {
  std::string solver, init, termination, message;
  double F_initial = 0, F_final = 0, time_s = 0;
  int iterations = 0;
  // rtr: the certificate of global optimality.
  std::optional<bool> certified;
  std::optional<int> rank;
  std::optional<double> lambda_min;
  // robust: the inlier threshold used, F over the edges kept, the edges rejected (from, to).
  bool robust = false;
  double threshold = 0, F_inliers = 0;
  std::vector<std::pair<Key, Key>> rejected;
  std::vector<Key> ids;
  RowMatrix estimate;
};

struct SolveRequest {
  std::string solver = "lm";
  std::optional<std::string> init;  ///< none: "file" when the file has poses, else "odometry"
  int max_iterations = 100;
  double relative_tolerance = 1e-5;
  std::optional<RobustSettings> robust;
  bool verbose = false;
};

InitMethod initOf(const SolveRequest& q, bool has_initial_estimate) {
  return parseInitMethod(q.init.value_or(has_initial_estimate ? "file" : "odometry"));
}

void fillRtr(const RtrSummary& s, SolveOutcome* out) {
  out->certified = s.certified;
  out->rank = s.rank;
  out->lambda_min = s.lambda_min;
  out->termination =
      s.certified ? "certified" : (s.relaxation_solved ? "relaxation_not_exact" : "not_certified");
  out->message = s.message;
}

// arbor_slam.RobustOptions' docstring, its online keywords from the table.
const std::string& robustOptionsDoc() {
  static const std::string doc = [] {
    std::string text =
        "kernel: tls | gm | cauchy | huber; threshold: c² on eᵀΩe (0: the χ² quantile of the "
        "edge's dimension at `confidence`); estimate_scale (batch only): scale that quantile by "
        "the estimated variance factor (--inlier-threshold auto). The online smoother's own "
        "options, by keyword, as `arbor replay`'s flags of the same names ('_' for '-'):";
    text += " " + keywordsDoc(onlineRobustOptionTable()) + "; each readable back";
    return text + "; OnlineSmoother only (solve() refuses them).";
  }();
  return doc;
}

// The online options from the keywords, by the online robust table (tools/cli/
// online_robust_table.h: the flags' names with '_' for '-'); an unknown keyword is a TypeError.
RobustOptions onlineOptions(const py::kwargs& keywords) {
  RobustOptions o;
  for (const auto& [key, value] : keywords) {
    setKeyword(onlineRobustOptionTable(), "RobustOptions", py::str(key), value, &o);
  }
  // The numbers by the options' own rule, which names the field (RobustOptions::problem).
  const std::string problem = o.problem();
  if (!problem.empty()) throw std::invalid_argument(problem);
  return o;
}

constexpr const char* kOnlineDoc =
    "an online option: `arbor replay`'s flag of this name ('_' for '-')";

RobustSettings robustSettingsOf(const std::string& kernel, double threshold, double confidence,
                                bool estimate_scale, const py::kwargs& online) {
  RobustSettings s;
  s.kernel = parseKernelKind(kernel);
  if (s.kernel == KernelKind::kNone)
    throw std::invalid_argument("kernel must be tls, gm, cauchy or huber, not 'none'");
  if (!(threshold >= 0))
    throw std::invalid_argument("threshold must be >= 0 (0: the chi2 quantile), not " +
                                std::to_string(threshold));
  if (!(confidence > 0 && confidence < 1))
    throw std::invalid_argument("confidence must be in (0, 1), not " + std::to_string(confidence));
  s.threshold = threshold;
  s.confidence = confidence;
  s.estimate_scale = estimate_scale;
  s.online = onlineOptions(online);
  return s;
}

// Every option by its keyword, in the constructor's order, the online ones by the table
// (to_dict, pickle, ==, repr).
py::dict robustDict(const RobustSettings& s) {
  py::dict d;
  d["kernel"] = toString(s.kernel);
  d["threshold"] = s.threshold;
  d["confidence"] = s.confidence;
  d["estimate_scale"] = s.estimate_scale;
  for (const OptionSpec<RobustOptions>& row : onlineRobustOptionTable())
    d[row.keyword.c_str()] = keywordValue(row, s.online);
  return d;
}

// The options a dict of robustDict's keywords names (pickle's state), checked as the
// constructor checks them.
RobustSettings robustFromDict(const py::dict& state) {
  py::dict d = py::reinterpret_steal<py::dict>(PyDict_Copy(state.ptr()));
  const auto take = [&](const char* key, py::object fallback) {
    py::object v = d.contains(key) ? py::object(d[key]) : fallback;
    if (d.contains(key)) PyDict_DelItemString(d.ptr(), key);
    return v;
  };
  const auto kernel = take("kernel", py::str("tls")).cast<std::string>();
  const double threshold = take("threshold", py::float_(0.0)).cast<double>();
  const double confidence = take("confidence", py::float_(0.99)).cast<double>();
  const bool estimate_scale = take("estimate_scale", py::bool_(false)).cast<bool>();
  return robustSettingsOf(kernel, threshold, confidence, estimate_scale, py::kwargs(d));
}

// RobustOptions(kernel=..., threshold=..., confidence=..., estimate_scale=...) and the online
// options that differ from their defaults: it evaluates back to equal options.
std::string robustRepr(const RobustSettings& s) {
  const py::dict mine = robustDict(s);
  const py::dict defaults = robustDict(RobustSettings{});
  std::string out = "RobustOptions(";
  int k = 0;
  for (const auto& [key, value] : mine) {
    const bool core = k++ < 4;
    if (core || !value.equal(defaults[key]))
      out += (core && k == 1 ? "" : ", ") + std::string(py::str(key)) + "=" +
             std::string(py::repr(value));
  }
  return out + ")";
}

// Whether any online option differs from RobustOptions' default (solve() refuses them).
bool differsFromDefault(const RobustOptions& o) {
  const RobustOptions d;
  for (const OptionSpec<RobustOptions>& row : onlineRobustOptionTable())
    if (row.get(o) != row.get(d)) return true;
  return false;
}

// As `arbor batch --robust`: GNC from the initialisation; with rtr, the certifiable solver on
// the inlier problem.
template <class G>
void solveRobust(const PoseGraph<G>& graph, const SolveRequest& q, BatchSolver solver,
                 const refine::BatchSolveSettings& settings, std::vector<G>* poses,
                 SolveOutcome* out) {
  if (differsFromDefault(q.robust->online))
    throw std::invalid_argument(
        "solve(): RobustOptions' online options (noise_scale, entry, corroboration_window, "
        "finalize_rounds, rules_off) are the OnlineSmoother's; solve() runs GNC from `init`");
  GncOptions options;
  options.kernel = q.robust->kernel;
  options.threshold = q.robust->threshold;
  options.confidence = q.robust->confidence;
  options.estimate_scale = q.robust->estimate_scale;
  options.outer.max_iterations = q.max_iterations;
  options.outer.relative_tolerance = q.relative_tolerance;
  options.verbose = q.verbose;
  GncResult gnc = solveGnc(graph, poses, options);
  out->F_initial = gnc.F_least_squares;
  out->iterations = gnc.iterations;
  out->time_s = gnc.time_s;
  out->termination = gnc.converged ? "converged" : "max_iterations";
  out->message = gnc.message;
  if (solver == BatchSolver::kRtr) {
    RtrOptions rtr = settings.rtr;
    rtr.verbose = q.verbose;
    const CertifiedInliers certified = certifyInliers(graph, &gnc, poses, rtr);
    fillRtr(certified.rtr, out);
    out->time_s += certified.rtr.time_s;
  }
  out->robust = true;
  out->threshold = gnc.threshold;
  out->F_final = gnc.F_all;
  out->F_inliers = gnc.F_inliers;
  for (int k = 0; k < graph.numEdges(); ++k)
    if (!gnc.trusted[k] && !gnc.inlier[k])
      out->rejected.emplace_back(graph.ids[graph.edges[k].i], graph.ids[graph.edges[k].j]);
}

template <class G>
SolveOutcome solve(const GraphObject<G>& object, const SolveRequest& q) {
  const PoseGraph<G>& graph = object.graph;
  const BatchSolver solver = refine::parseBatchSolver(q.solver, "solver");
  const bool own_start = refine::info(solver).own_start;
  if (own_start && q.init && *q.init != "chordal" && !q.robust)
    throw std::invalid_argument("solver " + q.solver +
                                " starts from its own chordal relaxation: init must be None or "
                                "'chordal', not '" +
                                *q.init + "'");
  if (solver == BatchSolver::kRtr && graph.numCustomFactors() > 0)
    throw std::invalid_argument(
        "solver rtr: the certifiable solver takes relative-pose edges only: " +
        std::to_string(graph.numCustomFactors()) + " custom factor(s) (the first '" +
        graph.custom_factors.front().name() + "'); use lm, gn or dogleg");
  if (q.max_iterations < 1)
    throw std::invalid_argument("max_iterations must be >= 1, not " +
                                std::to_string(q.max_iterations));
  if (!(q.relative_tolerance >= 0))
    throw std::invalid_argument("relative_tolerance must be >= 0, not " +
                                std::to_string(q.relative_tolerance));
  refine::BatchSolveSettings settings;
  settings.max_iterations = q.max_iterations;
  settings.relative_tolerance = q.relative_tolerance;
  settings.verbose = q.verbose;

  SolveOutcome out;
  out.solver = refine::toString(solver);
  std::vector<G> poses;
  {
    py::gil_scoped_release release;
    if (own_start && !q.robust) {
      out.init = "chordal";
      poses = chordalInitialization(graph);
      out.F_initial = objective(graph, poses);
      const refine::BatchSolve s = refine::runBatchSolver(solver, graph, &poses, settings);
      fillRtr(*s.rtr, &out);
      out.F_final = s.F_final;
      out.iterations = s.iterations;
      out.time_s = s.time_s;
    } else {
      const InitMethod init = initOf(q, graph.has_initial_estimate);
      out.init = toString(init);
      poses = initialize(graph, init);
      if (q.robust) {
        solveRobust(graph, q, solver, settings, &poses, &out);
      } else {
        const refine::BatchSolve s = refine::runBatchSolver(solver, graph, &poses, settings);
        out.F_initial = s.F_initial;
        out.F_final = s.F_final;
        out.iterations = s.iterations;
        out.time_s = s.time_s;
        out.termination = s.termination;
        out.message = s.message;
      }
    }
  }
  out.ids = graph.ids;
  out.estimate = posesToArray(poses);
  return out;
}

template <class G>
void defineSolveOf(py::module_& m) {
  m.def(
      "solve",
      [](const GraphObject<G>& graph, const std::string& solver,
         const std::optional<std::string>& init, int max_iterations, double relative_tolerance,
         const std::optional<RobustSettings>& robust, bool verbose) {
        return solve(
            graph, SolveRequest{solver, init, max_iterations, relative_tolerance, robust, verbose});
      },
      py::arg("graph"), py::arg("solver") = "lm", py::arg("init") = py::none(),
      py::arg("max_iterations") = 100, py::arg("relative_tolerance") = 1e-5,
      py::arg("robust") = py::none(), py::arg("verbose") = false,
      "Solves the graph in batch. solver: lm | gn | dogleg | rtr (rtr: the certifiable solver, "
      "from its own chordal relaxation); init: odometry | spanning-tree | chordal | file "
      "(default: file when the file has poses, else odometry); robust: an arbor_slam.RobustOptions "
      "(GNC as `arbor batch --robust`). Returns an arbor_slam.SolveResult.");
}

}  // namespace

void defineSolve(py::module_& m) {
  auto options =
      py::class_<RobustSettings>(m, "RobustOptions",
                                 "Robustness against false loop closures (the robust flags of "
                                 "`arbor batch` and `arbor replay`).")
          .def(py::init(&robustSettingsOf), py::arg("kernel") = "tls", py::arg("threshold") = 0.0,
               py::arg("confidence") = 0.99, py::arg("estimate_scale") = false,
               robustOptionsDoc().c_str())
          .def_property_readonly(
              "kernel", [](const RobustSettings& s) { return toString(s.kernel); },
              "tls | gm | cauchy | huber")
          .def_readonly("threshold", &RobustSettings::threshold, "c² on eᵀΩe (0: the χ² quantile)")
          .def_readonly("confidence", &RobustSettings::confidence, "the χ² quantile's confidence")
          .def_readonly("estimate_scale", &RobustSettings::estimate_scale,
                        "batch only: the quantile scaled by the estimated variance factor")
          .def("__repr__", &robustRepr, "The options that evaluate back to these.")
          .def("to_dict", &robustDict, "Every option by its keyword (RobustOptions(**d) makes it).")
          .def(
              "__eq__",
              [](const RobustSettings& a, const py::object& b) -> py::object {
                if (!py::isinstance<RobustSettings>(b))
                  return py::reinterpret_borrow<py::object>(Py_NotImplemented);
                return py::bool_(robustDict(a).equal(robustDict(b.cast<const RobustSettings&>())));
              },
              py::is_operator(), "Every option the same.")
          .def(py::pickle(&robustDict, &robustFromDict));
  // The online options, read-only, by the table: a str, an int or a float each.
  for (const OptionSpec<RobustOptions>& row : onlineRobustOptionTable()) {
    options.def_property_readonly(
        row.keyword.c_str(), [row](const RobustSettings& s) { return keywordValue(row, s.online); },
        kOnlineDoc);
  }

  Record<SolveOutcome>(m, "SolveResult",
                       "What arbor_slam.solve returns (docs/python.md, \"Results\").")
      .field("solver", &SolveOutcome::solver, "lm | gn | dogleg | rtr")
      .field("init", &SolveOutcome::init, "the initialisation: odometry | spanning-tree | ...")
      .field("F_initial", &SolveOutcome::F_initial, "F = Σ eᵀΩe at the start")
      .field("F_final", &SolveOutcome::F_final, "F at the estimate (robust: over every edge)")
      .field("iterations", &SolveOutcome::iterations, "the solver's iterations")
      .field("termination", &SolveOutcome::termination, "why it stopped")
      .field("message", &SolveOutcome::message, "the solver's message")
      .field("time_s", &SolveOutcome::time_s, "wall time of the solve")
      .field("certified", &SolveOutcome::certified, "rtr: certified optimal; else None")
      .field("rank", &SolveOutcome::rank, "rtr: the staircase's rank; else None")
      .field("lambda_min", &SolveOutcome::lambda_min, "rtr: the certificate's λ_min; else None")
      .field("robust", &SolveOutcome::robust, "solved with RobustOptions (GNC)")
      .field("threshold", &SolveOutcome::threshold, "robust: c² used")
      .field("F_inliers", &SolveOutcome::F_inliers, "robust: F over the edges kept")
      .field("rejected", &SolveOutcome::rejected, "robust: (from, to) of rejected edges")
      .field("ids", &SolveOutcome::ids, "the pose ids (int64, ascending)")
      .field("estimate", &SolveOutcome::estimate,
             "the estimate, one row per id (n×3 [x y θ] or n×7 [x y z qx qy qz qw])");
  defineSolveOf<SE2>(m);
  defineSolveOf<SE3>(m);
}

}  // namespace arbor::python
