// arbor_slam.solve: a batch solve of a Graph2 / Graph3 with any row of the solver table
// (tools/refine/batch_solvers.h: lm, gn, dogleg, rtr) from any initialisation, optionally
// robust (GNC, as `arbor batch --robust`), and arbor_slam.RobustOptions.
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <pybind11/stl.h>

#include "arbor_slam/core/gnc_solver.h"
#include "arbor_slam/core/initialization.h"
#include "arbor_slam/tools/refine/batch_solvers.h"
#include "bindings.h"
#include "conversions.h"
#include "graph_object.h"

namespace arbor::python {
namespace {

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

// The online smoother's options that `arbor replay`'s online robust flags set, by the flags'
// names with '_' for '-' (noise_scale is RobustOptions::scale).
constexpr std::pair<const char*, double RobustOptions::*> kOnlineReals[] = {
    {"final_confirm_margin", &RobustOptions::final_confirm_margin},
    {"end_confirm_margin", &RobustOptions::end_confirm_margin},
    {"rehold_growth", &RobustOptions::rehold_growth},
    {"end_scale_growth", &RobustOptions::end_scale_growth},
    {"end_backed_margin", &RobustOptions::end_backed_margin},
    {"left_out_backing_margin", &RobustOptions::left_out_backing_margin}};
constexpr std::pair<const char*, int RobustOptions::*> kOnlineInts[] = {
    {"corroboration_window", &RobustOptions::corroboration_window},
    {"finalize_rounds", &RobustOptions::finalize_rounds},
    {"end_rejected_partners", &RobustOptions::end_rejected_partners},
    {"end_scale_samples", &RobustOptions::end_scale_samples}};

// A value of the keyword `name`, as T, or a TypeError naming it.
template <class T>
T keywordValue(const std::string& name, const py::handle& value, const char* type) {
  try {
    return value.cast<T>();
  } catch (const py::cast_error&) {
    throw py::type_error("RobustOptions: " + name + " must be " + type + ", not " +
                         std::string(py::str(value.get_type().attr("__name__"))));
  }
}

// The enum named by the keyword `name` (parse: the enum's inverse of toString).
template <class Enum>
Enum keywordChoice(const std::string& name, const py::handle& value,
                   Enum (*parse)(const std::string&)) {
  try {
    return parse(keywordValue<std::string>(name, value, "a str"));
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument("RobustOptions: " + name + " " + e.what());
  }
}

// The online options from the keywords; anything else is a TypeError.
RobustOptions onlineOptions(const py::kwargs& keywords) {
  RobustOptions o;
  for (const auto& [key, value] : keywords) {
    const std::string name = py::str(key);
    if (name == "noise_scale") {
      o.scale = keywordChoice(name, value, parseNoiseScale);
    } else if (name == "entry") {
      o.entry = keywordChoice(name, value, parseEntryTest);
    } else if (name == "warm_up") {
      o.warm_up = keywordChoice(name, value, parseWarmUp);
    } else if (name == "scale_start") {
      o.scale_start = keywordChoice(name, value, parseScaleStart);
    } else if (name == "first_recheck") {
      o.first_recheck = keywordChoice(name, value, parseFirstRecheck);
    } else {
      bool known = false;
      for (const auto& [field, member] : kOnlineReals)
        if (name == field) {
          o.*member = keywordValue<double>(name, value, "a number");
          known = true;
        }
      for (const auto& [field, member] : kOnlineInts)
        if (name == field) {
          o.*member = keywordValue<int>(name, value, "an int");
          known = true;
        }
      if (!known) throw py::type_error("RobustOptions: unexpected keyword '" + name + "'");
    }
  }
  // The numbers by the options' own rule, which names the field (RobustOptions::problem).
  const std::string problem = o.problem();
  if (!problem.empty()) throw std::invalid_argument(problem);
  return o;
}

// Whether any online option differs from RobustOptions' default (solve() refuses them).
bool differsFromDefault(const RobustOptions& o) {
  const RobustOptions d;
  bool differs = o.scale != d.scale || o.entry != d.entry || o.warm_up != d.warm_up ||
                 o.scale_start != d.scale_start || o.first_recheck != d.first_recheck;
  for (const auto& [field, member] : kOnlineReals) differs = differs || o.*member != d.*member;
  for (const auto& [field, member] : kOnlineInts) differs = differs || o.*member != d.*member;
  return differs;
}

// As `arbor batch --robust`: GNC from the initialisation; with rtr, the certifiable solver on
// the inlier problem.
template <class G>
void solveRobust(const PoseGraph<G>& graph, const SolveRequest& q, BatchSolver solver,
                 const refine::BatchSolveSettings& settings, std::vector<G>* poses,
                 SolveOutcome* out) {
  if (differsFromDefault(q.robust->online))
    throw std::invalid_argument(
        "solve(): RobustOptions' online options (noise_scale, entry, warm_up, scale_start, "
        "first_recheck, corroboration_window, the margins, rounds and end-scale settings) are "
        "the OnlineSmoother's; solve() runs GNC from `init`");
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
          .def(py::init([](const std::string& kernel, double threshold, double confidence,
                           bool estimate_scale, const py::kwargs& online) {
                 RobustSettings s;
                 s.kernel = parseKernelKind(kernel);
                 if (s.kernel == KernelKind::kNone)
                   throw std::invalid_argument(
                       "kernel must be tls, gm, cauchy or huber, not 'none'");
                 if (!(threshold >= 0))
                   throw std::invalid_argument(
                       "threshold must be >= 0 (0: the chi2 quantile), not " +
                       std::to_string(threshold));
                 if (!(confidence > 0 && confidence < 1))
                   throw std::invalid_argument("confidence must be in (0, 1), not " +
                                               std::to_string(confidence));
                 s.threshold = threshold;
                 s.confidence = confidence;
                 s.estimate_scale = estimate_scale;
                 s.online = onlineOptions(online);
                 return s;
               }),
               py::arg("kernel") = "tls", py::arg("threshold") = 0.0, py::arg("confidence") = 0.99,
               py::arg("estimate_scale") = false,
               "kernel: tls | gm | cauchy | huber; threshold: c² on eᵀΩe (0: the χ² quantile of "
               "the edge's dimension at `confidence`); estimate_scale (batch only): scale that "
               "quantile by the estimated variance factor (--inlier-threshold auto). The online "
               "smoother's own options, by keyword, as `arbor replay`'s flags of the same names "
               "('_' for '-'): noise_scale (estimated | given), entry (innovation | residual), "
               "warm_up (hold | given), scale_start (at-most-last | median), first_recheck "
               "(replay | relinearized), corroboration_window, finalize_rounds, "
               "end_rejected_partners, "
               "end_scale_samples (ints), final_confirm_margin, end_confirm_margin, "
               "rehold_growth, end_scale_growth, end_backed_margin, left_out_backing_margin "
               "(numbers); OnlineSmoother only (solve() refuses them).")
          .def_property_readonly("kernel",
                                 [](const RobustSettings& s) { return toString(s.kernel); })
          .def_readonly("threshold", &RobustSettings::threshold)
          .def_readonly("confidence", &RobustSettings::confidence)
          .def_readonly("estimate_scale", &RobustSettings::estimate_scale)
          .def_property_readonly("noise_scale",
                                 [](const RobustSettings& s) { return toString(s.online.scale); })
          .def_property_readonly("entry",
                                 [](const RobustSettings& s) { return toString(s.online.entry); })
          .def_property_readonly("warm_up",
                                 [](const RobustSettings& s) { return toString(s.online.warm_up); })
          .def_property_readonly(
              "scale_start", [](const RobustSettings& s) { return toString(s.online.scale_start); })
          .def_property_readonly(
              "first_recheck",
              [](const RobustSettings& s) { return toString(s.online.first_recheck); })
          .def("__repr__", [](const RobustSettings& s) {
            return "<arbor_slam.RobustOptions kernel=" + toString(s.kernel) +
                   " threshold=" + std::to_string(s.threshold) +
                   " noise_scale=" + toString(s.online.scale) + ">";
          });
  for (const auto& [field, member] : kOnlineReals)
    options.def_property_readonly(
        field, [member = member](const RobustSettings& s) { return s.online.*member; });
  for (const auto& [field, member] : kOnlineInts)
    options.def_property_readonly(
        field, [member = member](const RobustSettings& s) { return s.online.*member; });

  py::class_<SolveOutcome>(m, "SolveResult", "What arbor_slam.solve returns.")
      .def_readonly("solver", &SolveOutcome::solver)
      .def_readonly("init", &SolveOutcome::init)
      .def_readonly("F_initial", &SolveOutcome::F_initial)
      .def_readonly("F_final", &SolveOutcome::F_final)
      .def_readonly("iterations", &SolveOutcome::iterations)
      .def_readonly("termination", &SolveOutcome::termination)
      .def_readonly("message", &SolveOutcome::message)
      .def_readonly("time_s", &SolveOutcome::time_s)
      .def_readonly("certified", &SolveOutcome::certified, "rtr: certified optimal; else None")
      .def_readonly("rank", &SolveOutcome::rank, "rtr: the staircase's rank; else None")
      .def_readonly("lambda_min", &SolveOutcome::lambda_min, "rtr: the certificate's λ_min")
      .def_readonly("robust", &SolveOutcome::robust)
      .def_readonly("threshold", &SolveOutcome::threshold, "robust: c² used")
      .def_readonly("F_inliers", &SolveOutcome::F_inliers, "robust: F over the edges kept")
      .def_readonly("rejected", &SolveOutcome::rejected, "robust: (from, to) of rejected edges")
      .def_property_readonly("ids", [](const SolveOutcome& s) { return idsToArray(s.ids); })
      .def_readonly("estimate", &SolveOutcome::estimate,
                    "the estimate, one row per id (n×3 [x y θ] or n×7 [x y z qx qy qz qw])")
      .def("__repr__", [](const SolveOutcome& s) {
        return "<arbor_slam.SolveResult " + s.solver + " F_final=" + std::to_string(s.F_final) +
               " " + s.termination + ">";
      });
  defineSolveOf<SE2>(m);
  defineSolveOf<SE3>(m);
}

}  // namespace arbor::python
