// arbor_slam.OnlineSmoother2 / OnlineSmoother3: the online smoother (bayestree/online_smoother.h)
// with poses named by ids, edges and priors in any order, updates, the estimate and statistics
// as numpy arrays and dicts, and marginal and joint covariances from the Bayes tree.
#include <algorithm>
#include <limits>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <pybind11/stl.h>

#include "arbor_slam/bayestree/online_smoother.h"
#include "arbor_slam/core/finite_pose.h"
#include "arbor_slam/core/information.h"
#include "arbor_slam/core/prior_factors.h"
#include "arbor_slam/core/relative_pose_factor.h"
#include "arbor_slam/tools/cli/smoother_table.h"
#include "arbor_slam/tools/refine/batch_refiner.h"
#include "bindings.h"
#include "conversions.h"
#include "custom_factor_object.h"
#include "graph_object.h"
#include "option_keywords.h"
#include "smoother_results.h"

namespace arbor::python {
namespace {

/// "accepted" or "duplicate"; a rejected edge or prior raises ValueError with its reason.
std::string statusOrThrow(const EdgeResult& r) {
  if (r.status == EdgeStatus::kRejected) throw std::invalid_argument(r.reason);
  return toString(r.status);
}

void throwUnlessApplied(const EdgeSwitchResult& r) {
  if (!r.applied()) throw std::invalid_argument(r.reason);
}

// A batch refinement's figures, robust ones as Σρ; the rtr ones None for lm.
RefineResult refineResultOf(const refine::BatchRun& b) {
  RefineResult r;
  r.poses = b.poses;
  r.edges = b.edges;
  r.F_incremental = b.F_incremental;
  r.F_batch = b.F_batch;
  r.relative_gap = b.relative_gap;
  r.winner = b.winner;
  r.margin = b.margin;
  r.max_translation_diff = b.max_translation_diff;
  r.max_rotation_diff = b.max_rotation_diff;
  r.iterations = b.iterations;
  r.time_s = b.time_s;
  if (b.rank > 0) {
    r.certified = b.certified;
    r.rank = b.rank;
    r.lambda_min = b.lambda_min;
  }
  r.robust = b.robust;
  r.judged = b.judged;
  r.rejected = b.rejected;
  r.inlier_threshold = b.threshold;
  r.rtr_skipped = b.rtr_skipped;
  r.reseeded = b.reseeded;
  r.reseed_rejected = b.reseed_rejected;
  return r;
}

template <class G>
OnlineSmootherOptions<G> optionsOf(const std::optional<RobustSettings>& robust,
                                   const py::kwargs& keywords) {
  OnlineSmootherOptions<G> o;
  // The smoother's keywords by their rows of the smoother table (tools/cli/smoother_table.h).
  for (const auto& [key, value] : keywords)
    setKeyword(cli::smootherOptionTable(), "OnlineSmoother", py::str(key), value, &o.smoother);
  // The smoother refuses a budget beside dogleg; the robust layer is this one's.
  if (o.smoother.solve_budget_mb > 0 && robust)
    throw std::invalid_argument(
        "solve_budget_mb needs no robust options (the robust layer judges closures against the "
        "estimate, which a budget leaves partly deferred)");
  if (robust) {
    if (robust->estimate_scale)
      throw std::invalid_argument(
          "RobustOptions.estimate_scale is for batch solves only (the online smoother's "
          "threshold is given or the chi2 quantile)");
    RobustOptions r = robust->online;
    r.kernel = robust->kernel;
    r.threshold = robust->threshold;
    r.confidence = robust->confidence;
    const std::string problem = r.problem();
    if (!problem.empty()) throw std::invalid_argument(problem);
    o.robust = r;
  }
  return o;
}

// The constructor's docstring, its keywords from the smoother table.
const std::string& smootherDoc() {
  static const std::string doc =
      "robust: an arbor_slam.RobustOptions (online GNC per loop closure, as `arbor replay "
      "--robust`); "
      "by keyword, `arbor replay`'s smoother flags of the same names ('_' for '-'; "
      "wildfire_threshold is --wildfire): " +
      keywordsDoc(cli::smootherOptionTable()) +
      ". threads 0: one per core, at most 4; the estimate does not depend on it.";
  return doc;
}

// " (added before it: N, duplicates: M; they stay, waiting for update())".
std::string addedSoFar(int accepted, int duplicate) {
  if (accepted + duplicate == 0) return " (nothing added)";
  return " (added before it: " + std::to_string(accepted) +
         ", duplicates: " + std::to_string(duplicate) + "; they stay, waiting for update())";
}

// Adds a note (PEP 678, Python 3.11) to the Python exception being raised.
void addNote(const std::string& note) {
  PyObject *type = nullptr, *value = nullptr, *trace = nullptr;
  PyErr_Fetch(&type, &value, &trace);
  PyErr_NormalizeException(&type, &value, &trace);
  if (value != nullptr && PyObject_HasAttrString(value, "add_note")) {
    PyObject* r = PyObject_CallMethod(value, "add_note", "s", note.c_str());
    if (r == nullptr) PyErr_Clear();
    Py_XDECREF(r);
  }
  if (trace != nullptr && value != nullptr) PyException_SetTraceback(value, trace);
  PyErr_Restore(type, value, trace);
}

// add_graph's check of the whole graph before anything is added: every refusal the online
// smoother would make (the values of edges and priors, a custom factor's poses: known or
// created by the graph's edges and priors, and in one component once its edges are in), and
// each custom factor's functions once at the graph's poses (or the estimates of known ones).
// Throws ValueError (or what a function raised) naming the element; changes nothing.
template <class G>
void checkGraphFirst(const OnlineSmoother<G>& s, const PoseGraph<G>& graph, bool guesses) {
  const auto refuse = [](const std::string& what, const std::string& why) {
    throw std::invalid_argument("add_graph: " + what + ": " + why + " (nothing added)");
  };
  // Components as the online smoother will have them: known poses by their component, the
  // graph's edges joining them.
  std::map<Key, Key> parent;
  const auto find = [&](Key k) {
    for (auto it = parent.find(k); it != parent.end(); it = parent.find(k)) k = it->second;
    return k;
  };
  const auto unite = [&](Key a, Key b) {
    const Key ra = find(a), rb = find(b);
    if (ra != rb) parent[ra] = rb;
  };
  std::set<Key> created;
  // A known pose stands for its component through a key of its own (below any id: −1 − c).
  std::map<int, Key> component_key;
  const auto node = [&](Key id) -> Key {
    if (!s.hasPose(id)) return id;
    const int c = s.componentOf(id);
    auto it = component_key.find(c);
    if (it != component_key.end()) {
      unite(id, it->second);
      return id;
    }
    const Key k = std::numeric_limits<Key>::min() + static_cast<Key>(component_key.size());
    component_key[c] = k;
    unite(id, k);
    return id;
  };
  for (const auto& edge : graph.edges) {
    const Key from = graph.ids[edge.i], to = graph.ids[edge.j];
    const std::string what = "edge " + std::to_string(from) + " -> " + std::to_string(to);
    if (!allFinite(edge.measurement) || !edge.information.allFinite())
      refuse(what, "NaN or infinite value");
    if (from == to) refuse(what, "self-loop on pose " + std::to_string(from));
    const std::string problem = informationProblem(edge.information);
    if (!problem.empty()) refuse(what, "bad information: " + problem);
    const std::string far = translationProblem(edge.measurement);
    if (!far.empty()) refuse(what, "bad measurement: " + far);
    unite(node(from), node(to));
    created.insert(from);
    created.insert(to);
  }
  for (const auto& p : graph.pose_priors) {
    const std::string what = "pose prior on " + std::to_string(graph.ids[p.i]);
    if (!allFinite(p.measurement) || !allFinite(p.offset) || !p.information.allFinite())
      refuse(what, "NaN or infinite value");
    try {
      PosePriorFactor<G>::make(0, p.measurement, p.information, p.offset);
    } catch (const std::invalid_argument& e) {
      refuse(what, e.what());
    }
    node(graph.ids[p.i]);
    created.insert(graph.ids[p.i]);
  }
  for (const auto& p : graph.position_priors) {
    const std::string what = "position prior on " + std::to_string(graph.ids[p.i]);
    if (!p.position.allFinite() || !p.information.allFinite())
      refuse(what, "NaN or infinite value");
    try {
      PositionPriorFactor<G>::make(0, p.position, p.information);
    } catch (const std::invalid_argument& e) {
      refuse(what, e.what());
    }
    node(graph.ids[p.i]);
    created.insert(graph.ids[p.i]);
  }
  for (const auto& c : graph.custom_factors) {
    const Key id = graph.ids[c.i];
    const std::string what = "custom factor '" + c.name() + "' on " + std::to_string(id);
    std::vector<G> at;
    for (int k = 0; k < c.arity(); ++k) {
      const Key key = graph.ids[k == 0 ? c.i : c.j];
      if (!s.hasPose(key) && created.count(key) == 0)
        refuse(what, "unknown pose id " + std::to_string(key) +
                         " (an edge or a prior creates a pose, a custom factor cannot)");
      if (s.hasPose(key))
        at.push_back(s.estimate(key));
      else if (guesses && graph.has_initial_estimate)
        at.push_back(graph.poses[static_cast<size_t>(k == 0 ? c.i : c.j)]);
    }
    if (c.arity() == 2 && find(node(graph.ids[c.i])) != find(node(graph.ids[c.j])))
      refuse(what, "its poses are in two components; an edge must join them first");
    CustomFactor<G> local = c;
    local.i = 0;
    local.j = c.arity() == 2 ? 1 : -1;
    if (static_cast<int>(at.size()) < c.arity()) continue;  // no value to evaluate it at
    try {
      typename FactorModel<G>::Jacobians J;
      local.error(at, &J);
    } catch (const std::invalid_argument& e) {
      refuse(what, e.what());
    } catch (py::error_already_set& e) {
      e.restore();
      addNote("add_graph: " + what + " raised at the graph's poses (nothing added)");
      throw py::error_already_set();
    }
  }
}

template <class G>
void defineSmootherOf(py::module_& m, const char* name) {
  using Smoother = OnlineSmoother<G>;
  constexpr int k = G::kDoF;
  constexpr int d = G::kDim;
  py::class_<Smoother>(m, name,
                       "The online smoother: poses named by ids, edges and priors in any order, "
                       "an incremental update at a time (docs/python.md).")
      .def(py::init([](const std::optional<RobustSettings>& robust, const py::kwargs& keywords) {
             return std::make_unique<Smoother>(optionsOf<G>(robust, keywords));
           }),
           py::arg("robust") = py::none(), smootherDoc().c_str())
      .def(
          "add_edge",
          [](Smoother& s, Key from, Key to, const Eigen::VectorXd& z,
             const Eigen::MatrixXd& information, bool trusted) {
            return statusOrThrow(s.addEdge(from, to, poseFromArray<G>(z, "measurement"),
                                           squareFromArray<k>(information, "information"),
                                           trusted ? EdgeTrust::kTrusted : EdgeTrust::kByRule));
          },
          py::arg("from_id"), py::arg("to_id"), py::arg("measurement"), py::arg("information"),
          py::arg("trusted") = false,
          "Adds the measurement of pose to_id in the frame of from_id with its information "
          "matrix; returns 'accepted' or 'duplicate', raises ValueError if rejected.")
      .def(
          "add_pose_prior",
          [](Smoother& s, Key id, const Eigen::VectorXd& z, const Eigen::MatrixXd& information,
             const std::optional<Eigen::VectorXd>& offset) {
            const G o = offset ? poseFromArray<G>(*offset, "offset") : G::Identity();
            return statusOrThrow(s.addPosePrior(id, poseFromArray<G>(z, "prior"),
                                                squareFromArray<k>(information, "information"), o));
          },
          py::arg("id"), py::arg("prior"), py::arg("information"), py::arg("offset") = py::none(),
          "A prior on pose id in the world frame (on id·offset with a sensor offset).")
      .def(
          "add_position_prior",
          [](Smoother& s, Key id, const Eigen::VectorXd& p, const Eigen::MatrixXd& information) {
            if (p.size() != d || !p.allFinite())
              throw std::invalid_argument("position: expected " + std::to_string(d) +
                                          " finite numbers, got " + std::to_string(p.size()));
            return statusOrThrow(
                s.addPositionPrior(id, p, squareFromArray<d>(information, "information")));
          },
          py::arg("id"), py::arg("position"), py::arg("information"),
          "A prior on the position of pose id in the world frame (GPS in a local frame).")
      .def(
          "add_graph",
          [](Smoother& s, const GraphObject<G>& g, bool initial_guesses) {
            const PoseGraph<G>& graph = g.graph;
            checkGraphFirst(s, graph, initial_guesses);  // every refusal, before any change
            if (initial_guesses && graph.has_initial_estimate)
              for (int i = 0; i < graph.numPoses(); ++i)
                s.setInitialGuess(graph.ids[i], graph.poses[i]);
            int accepted = 0, duplicate = 0;
            const auto count = [&](const EdgeResult& r, const std::string& what) {
              if (r.status == EdgeStatus::kRejected)
                throw std::invalid_argument("add_graph: " + what + ": " + r.reason +
                                            addedSoFar(accepted, duplicate));
              ++(r.status == EdgeStatus::kDuplicate ? duplicate : accepted);
            };
            // Edges in order of their later pose (file order among ties), as `arbor replay`.
            std::vector<int> order(graph.edges.size());
            for (size_t e = 0; e < order.size(); ++e) order[e] = static_cast<int>(e);
            const auto later = [&](int e) { return std::max(graph.edges[e].i, graph.edges[e].j); };
            std::stable_sort(order.begin(), order.end(),
                             [&](int a, int b) { return later(a) < later(b); });
            for (int e : order) {
              const auto& edge = graph.edges[e];
              const Key from = graph.ids[edge.i], to = graph.ids[edge.j];
              count(s.addEdge(from, to, edge.measurement, edge.information),
                    "edge " + std::to_string(from) + " -> " + std::to_string(to));
            }
            for (const auto& p : graph.pose_priors)
              count(s.addPosePrior(graph.ids[p.i], p.measurement, p.information, p.offset),
                    "pose prior on " + std::to_string(graph.ids[p.i]));
            for (const auto& p : graph.position_priors)
              count(s.addPositionPrior(graph.ids[p.i], p.position, p.information),
                    "position prior on " + std::to_string(graph.ids[p.i]));
            for (const auto& c : graph.custom_factors) {
              const std::optional<Key> id2 =
                  c.j < 0 ? std::nullopt : std::optional<Key>(graph.ids[c.j]);
              EdgeResult r;
              try {  // its functions run here (its gauge information at the estimates)
                r = s.addFactor(c, graph.ids[c.i], id2);
              } catch (py::error_already_set& e) {
                e.restore();
                addNote("add_graph: custom factor '" + c.name() + "' on " +
                        std::to_string(graph.ids[c.i]) + " raised" +
                        addedSoFar(accepted, duplicate));
                throw py::error_already_set();
              }
              count(r, "custom factor '" + c.name() + "' on " + std::to_string(graph.ids[c.i]));
            }
            return AddGraphResult{accepted, duplicate};
          },
          py::arg("graph"), py::arg("initial_guesses") = true,
          "Adds every edge and prior of a Graph2/Graph3 (read or built in memory): edges in "
          "order of their later pose, then the priors, then the custom factors; with "
          "initial_guesses (and a graph with poses) each new pose starts at the graph's value. "
          "`fixed` poses are not held (the smoother's gauge is its first pose or the priors). "
          "Call update() after. Returns an arbor_slam.AddGraphResult (accepted, duplicate). All "
          "or nothing for every refusal: the graph is checked whole first, and a ValueError "
          "names the first refused element with nothing added. A custom factor whose own "
          "function raises when it is added (its gauge information at the estimates) stops "
          "add_graph there: that exception, with a note of how much was added (kept, "
          "consistent, waiting for update()).")
      .def(
          "add_factor",
          [](Smoother& s, const CustomFactorObject<G>& f) {
            const std::optional<Key> id2 =
                f.keys.size() == 2 ? std::optional<Key>(f.keys[1]) : std::nullopt;
            const CustomFactor<G> factor = f.make(0, id2 ? 1 : -1);
            // Evaluated once here at the estimates, so that an exception of its functions (or a
            // wrong shape) is raised before the smoother holds it: addFactor evaluates it too.
            std::vector<G> at;
            for (Key id : f.keys)
              if (s.hasPose(id)) at.push_back(s.estimate(id));
            if (at.size() == f.keys.size()) {
              typename FactorModel<G>::Jacobians J;
              factor.error(at, &J);
            }
            return statusOrThrow(s.addFactor(factor, f.keys[0], id2));
          },
          py::arg("factor"),
          "Adds a factor of your own (an arbor_slam.CustomFactor2/CustomFactor3) on poses an edge "
          "or a "
          "prior created already (a binary one's in one component); returns 'accepted', raises "
          "ValueError with the reason if rejected. Its functions run during update() and "
          "finalize(), under the GIL, from the smoother's threads; an exception they raise is "
          "raised by that call.")
      .def(
          "disable_edge",
          [](Smoother& s, Key a, Key b) { throwUnlessApplied(s.disableEdge(a, b)); },
          py::arg("from_id"), py::arg("to_id"),
          "Takes back every edge between the two ids (from the next update on); raises "
          "ValueError with the reason when refused.")
      .def(
          "enable_edge", [](Smoother& s, Key a, Key b) { throwUnlessApplied(s.enableEdge(a, b)); },
          py::arg("from_id"), py::arg("to_id"),
          "Gives back the edges disable_edge took (from the next update on); raises ValueError "
          "with the reason when refused.")
      .def(
          "update",
          [](Smoother& s) {
            UpdateStats st;
            {
              py::gil_scoped_release release;
              st = s.update();
            }
            return st;
          },
          "One incremental update over the edges and priors added since the last; returns its "
          "statistics (an arbor_slam.UpdateStats).")
      .def(
          "finalize",
          [](Smoother& s) {
            UpdateStats st;
            {
              py::gil_scoped_release release;
              st = s.finalize();
            }
            return st;
          },
          "Relinearises everything and iterates to convergence (the end of a replay); returns "
          "its statistics (an arbor_slam.UpdateStats).")
      .def(
          "refine",
          [](Smoother& s, const std::string& solver, bool reseed) {
            refine::RefinerOptions options;
            options.solver = refine::parseBatchSolver(solver, "solver", /*refinement_only=*/true);
            options.synchronous = true;
            options.reseed = reseed;
            refine::BatchRefiner<G> refiner(options);
            const PoseGraph<G> snapshot = s.snapshot();
            std::optional<refine::BatchOutcome<G>> out;
            {
              py::gil_scoped_release release;
              const std::int64_t updates = s.stats().updates;
              if (!refiner.start(s, updates))
                throw std::invalid_argument(
                    "refine: nothing to solve yet (fewer than 2 poses or no edge updated)");
              out = refiner.collect(true);
              if (reseed) refiner.reseed(s, &*out, updates);
            }
            RefineResult r = refineResultOf(out->run);
            r.ids = snapshot.ids;
            r.estimate = posesToArray(out->batch);
            return r;
          },
          py::arg("solver") = "lm", py::arg("reseed") = false,
          "A batch refinement of everything updated so far, on request (as `arbor replay "
          "--batch`): lm, or rtr (the certifiable solver, keep-best with LM); with robust options "
          "GNC, before finalize() with every closure free at the c² in use, after it from the "
          "smoother's classification (what it does not hold as settled inliers held out, taken "
          "back within its end's bound), for rtr certifying the inlier problem. reseed: the "
          "winner's estimate becomes the linearisation point when it lowers the cost. Returns "
          "an arbor_slam.RefineResult: the run's figures (F_* are Σρ when robust), ids and the "
          "batch "
          "estimate.")
      .def(
          "solve_deferred",
          [](Smoother& s, double budget_mb) {
            UpdateStats st;
            {
              py::gil_scoped_release release;
              st = s.solveDeferred(budget_mb);
            }
            return st;
          },
          py::arg("budget_mb") = 0.0,
          "With solve_budget_mb: solves the cliques the budget deferred (all, or about "
          "budget_mb of them); returns the statistics (cliques_deferred: those left).")
      .def_property_readonly(
          "cliques_deferred", [](const Smoother& s) { return s.smoother().cliquesDeferred(); },
          "With solve_budget_mb: the cliques whose solve the budget deferred.")
      .def("objective", &Smoother::objective,
           "F = Σ eᵀΩe at the estimate (disabled edges left out)")
      .def("has_pose", &Smoother::hasPose, py::arg("id"),
           "True when pose id is in the smoother (an accepted edge or prior made it)")
      .def_property_readonly(
          "num_poses", [](const Smoother& s) { return s.stats().poses; }, "number of poses")
      .def(
          "estimate", [](const Smoother& s, Key id) { return poseToArray(s.estimate(id)); },
          py::arg("id"), "The estimate of pose id as a row ([x y θ] or [x y z qx qy qz qw]).")
      .def(
          "estimates",
          [](const Smoother& s) {
            const std::map<Key, G> all = s.estimates();
            std::vector<Key> ids;
            std::vector<G> poses;
            for (const auto& [id, x] : all) {
              ids.push_back(id);
              poses.push_back(x);
            }
            return py::make_tuple(idsToArray(ids), posesToArray(poses));
          },
          "(ids ascending, poses one row each: n×3 [x y θ] or n×7 [x y z qx qy qz qw])")
      .def(
          "stats", [](const Smoother& s) { return s.stats(); },
          "The online layer's counts and the last update's statistics (an arbor_slam.OnlineStats).")
      .def(
          "marginal_covariance",
          [](const Smoother& s, Key id) {
            typename Smoother::Matrix c;
            {
              py::gil_scoped_release release;
              c = s.marginalCovariance(id);
            }
            return Eigen::MatrixXd(c);
          },
          py::arg("id"),
          "The k×k marginal covariance of pose id (k = 3 in 2D, 6 in 3D; tangent order "
          "[translation; rotation] of x ⊞ τ), after the last update, relative to its "
          "component's anchor.")
      .def(
          "joint_marginal_covariance",
          [](const Smoother& s, Key a, Key b) {
            Eigen::Matrix<double, 2 * k, 2 * k> c;
            {
              py::gil_scoped_release release;
              c = s.jointMarginalCovariance(a, b);
            }
            return Eigen::MatrixXd(c);
          },
          py::arg("a"), py::arg("b"),
          "The 2k×2k joint covariance [[Σ_aa, Σ_ab], [Σ_ba, Σ_bb]] of poses a and b.")
      .def(
          "closures",
          [](const Smoother& s) {
            std::vector<Closure> out;
            for (const ClosureReport& c : s.closures())
              out.push_back({c.from, c.to, c.weight, c.residual, toString(c.status), c.graduating});
            return out;
          },
          "With robust options: every loop closure's weight and status (inlier, outlier, "
          "trusted, excluded).")
      .def("__repr__", [name](const Smoother& s) {
        return std::string("<arbor_slam.") + name + ": " + std::to_string(s.stats().poses) +
               " poses, " + std::to_string(s.stats().updates) + " updates>";
      });
}

}  // namespace

void defineSmoother(py::module_& m) {
  defineSmootherOf<SE2>(m, "OnlineSmoother2");
  defineSmootherOf<SE3>(m, "OnlineSmoother3");
}

}  // namespace arbor::python
