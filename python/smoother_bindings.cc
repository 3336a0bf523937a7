// arbor_slam.OnlineSmoother2 / OnlineSmoother3: the online smoother (bayestree/online_smoother.h)
// with poses named by ids, edges and priors in any order, updates, the estimate and statistics
// as numpy arrays and dicts, and marginal and joint covariances from the Bayes tree.
#include <algorithm>
#include <optional>
#include <string>
#include <vector>

#include <pybind11/stl.h>

#include "arbor_slam/bayestree/online_smoother.h"
#include "arbor_slam/tools/refine/batch_refiner.h"
#include "bindings.h"
#include "conversions.h"
#include "custom_factor_object.h"
#include "graph_object.h"

namespace arbor::python {
namespace {

py::dict statsDict(const UpdateStats& s) {
  py::dict d;
  d["new_factors"] = s.new_factors;
  d["new_variables"] = s.new_variables;
  d["cliques_reeliminated"] = s.cliques_reeliminated;
  d["variables_reeliminated"] = s.variables_reeliminated;
  d["cliques_updated"] = s.cliques_updated;
  d["variables_relinearized"] = s.variables_relinearized;
  d["indeterminate_cliques"] = s.indeterminate_cliques;
  d["cliques_solved"] = s.cliques_solved;
  d["cliques_deferred"] = s.cliques_deferred;
  d["time_s"] = s.time_s;
  return d;
}

py::dict statsDict(const OnlineStats& s) {
  py::dict d;
  d["poses"] = s.poses;
  d["edges_accepted"] = s.edges_accepted;
  d["edges_duplicate"] = s.edges_duplicate;
  d["edges_rejected"] = s.edges_rejected;
  d["priors_accepted"] = s.priors_accepted;
  d["priors_rejected"] = s.priors_rejected;
  d["components"] = s.components;
  d["joins"] = s.joins;
  d["anchors_released"] = s.anchors_released;
  d["updates"] = s.updates;
  d["total_update_time_s"] = s.total_update_time_s;
  d["edges_disabled"] = s.edges_disabled;
  d["pairs_disabled"] = s.pairs_disabled;
  d["closures_inlier"] = s.closures_inlier;
  d["closures_outlier"] = s.closures_outlier;
  d["closures_trusted"] = s.closures_trusted;
  d["closures_excluded"] = s.closures_excluded;
  d["closures_graduating"] = s.closures_graduating;
  d["closures_unconfirmed"] = s.closures_unconfirmed;
  d["rechecks_bounded"] = s.rechecks_bounded;
  d["closures_left_out"] = s.closures_left_out;
  d["closures_disowned"] = s.closures_disowned;
  d["closures_kept_at_word"] = s.closures_kept_at_word;
  d["graduation_steps"] = s.graduation_steps;
  d["graduation_updates"] = s.graduation_updates;
  d["warm_up_relinearizations"] = s.warm_up_relinearizations;
  d["closure_threshold"] = s.closure_threshold;
  d["closure_threshold_at_end"] = s.closure_threshold_at_end;
  d["noise_scale"] = s.noise_scale;
  d["noise_samples"] = s.noise_samples;
  d["noise_scale_estimated"] = s.noise_scale_estimated;
  d["reseeds"] = s.reseeds;
  d["total_reseed_time_s"] = s.total_reseed_time_s;
  d["last_update"] = statsDict(s.last_update);
  return d;
}

/// "accepted" or "duplicate"; a rejected edge or prior raises ValueError with its reason.
std::string statusOrThrow(const EdgeResult& r) {
  if (r.status == EdgeStatus::kRejected) throw std::invalid_argument(r.reason);
  return toString(r.status);
}

void throwUnlessApplied(const EdgeSwitchResult& r) {
  if (!r.applied()) throw std::invalid_argument(r.reason);
}

// A batch refinement's figures (tools/refine/batch_refiner.h BatchRun), robust ones as Σρ.
py::dict runDict(const refine::BatchRun& b) {
  py::dict d;
  d["poses"] = b.poses;
  d["edges"] = b.edges;
  d["F_incremental"] = b.F_incremental;
  d["F_batch"] = b.F_batch;
  d["relative_gap"] = b.relative_gap;
  d["winner"] = b.winner;
  d["margin"] = b.margin;
  d["max_translation_diff"] = b.max_translation_diff;
  d["max_rotation_diff"] = b.max_rotation_diff;
  d["iterations"] = b.iterations;
  d["time_s"] = b.time_s;
  d["certified"] = b.rank > 0 ? py::object(py::bool_(b.certified)) : py::none();
  d["rank"] = b.rank > 0 ? py::object(py::int_(b.rank)) : py::none();
  d["lambda_min"] = b.rank > 0 ? py::object(py::float_(b.lambda_min)) : py::none();
  d["robust"] = b.robust;
  d["judged"] = b.judged;
  d["rejected"] = b.rejected;
  d["inlier_threshold"] = b.threshold;
  d["rtr_skipped"] = b.rtr_skipped;
  d["reseeded"] = b.reseeded;
  d["reseed_rejected"] = b.reseed_rejected;
  return d;
}

template <class G>
OnlineSmootherOptions<G> optionsOf(const std::optional<RobustSettings>& robust, int threads,
                                   double relinearize_translation, double relinearize_rotation,
                                   int relinearize_skip, double wildfire, bool dogleg,
                                   double solve_budget_mb) {
  OnlineSmootherOptions<G> o;
  if (threads < 0)
    throw std::invalid_argument("threads must be >= 0, not " + std::to_string(threads));
  if (relinearize_skip < 1)
    throw std::invalid_argument("relinearize_skip must be >= 1, not " +
                                std::to_string(relinearize_skip));
  if (!(relinearize_translation >= 0) || !(relinearize_rotation >= 0) || !(wildfire >= 0))
    throw std::invalid_argument("relinearisation and wildfire thresholds must be >= 0");
  o.smoother.threads = threads;
  o.smoother.relinearize_threshold_translation = relinearize_translation;
  o.smoother.relinearize_threshold_rotation = relinearize_rotation;
  o.smoother.relinearize_skip = relinearize_skip;
  o.smoother.wildfire_threshold = wildfire;
  o.smoother.dogleg = dogleg;
  // The smoother refuses a bad budget and one beside dogleg; the robust layer is this one's.
  if (solve_budget_mb > 0 && robust)
    throw std::invalid_argument(
        "solve_budget_mb needs no robust options (the robust layer judges closures against the "
        "estimate, which a budget leaves partly deferred)");
  o.smoother.solve_budget_mb = solve_budget_mb;
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

template <class G>
void defineSmootherOf(py::module_& m, const char* name) {
  using Smoother = OnlineSmoother<G>;
  constexpr int k = G::kDoF;
  constexpr int d = G::kDim;
  const SmootherOptions defaults;
  py::class_<Smoother>(m, name,
                       "The online smoother: poses named by ids, edges and priors in any order, "
                       "an incremental update at a time (docs/python.md).")
      .def(
          py::init([](const std::optional<RobustSettings>& robust, int threads, double rt,
                      double rr, int skip, double wildfire, bool dogleg, double budget) {
            return std::make_unique<Smoother>(
                optionsOf<G>(robust, threads, rt, rr, skip, wildfire, dogleg, budget));
          }),
          py::arg("robust") = py::none(), py::arg("threads") = defaults.threads,
          py::arg("relinearize_threshold_translation") = defaults.relinearize_threshold_translation,
          py::arg("relinearize_threshold_rotation") = defaults.relinearize_threshold_rotation,
          py::arg("relinearize_skip") = defaults.relinearize_skip,
          py::arg("wildfire_threshold") = defaults.wildfire_threshold,
          py::arg("dogleg") = defaults.dogleg,
          py::arg("solve_budget_mb") = defaults.solve_budget_mb,
          "robust: an arbor_slam.RobustOptions (online GNC per loop closure, as `arbor replay "
          "--robust`); the rest as `arbor replay`'s smoother flags (threads 0: one per core, "
          "at most 4; the estimate does not depend on it; solve_budget_mb as "
          "--solve-budget-mb).")
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
            if (initial_guesses && graph.has_initial_estimate)
              for (int i = 0; i < graph.numPoses(); ++i)
                s.setInitialGuess(graph.ids[i], graph.poses[i]);
            int accepted = 0, duplicate = 0;
            const auto count = [&](const EdgeResult& r, const std::string& what) {
              if (r.status == EdgeStatus::kRejected)
                throw std::invalid_argument("add_graph: " + what + ": " + r.reason);
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
              count(s.addFactor(c, graph.ids[c.i], id2),
                    "custom factor '" + c.name() + "' on " + std::to_string(graph.ids[c.i]));
            }
            py::dict out;
            out["accepted"] = accepted;
            out["duplicate"] = duplicate;
            return out;
          },
          py::arg("graph"), py::arg("initial_guesses") = true,
          "Adds every edge and prior of a Graph2/Graph3 (read or built in memory): edges in "
          "order of their later pose, then the priors, then the custom factors; with "
          "initial_guesses (and a graph with "
          "poses) each new pose starts at the graph's value. `fixed` poses are not held (the "
          "smoother's gauge is its first pose or the priors). Call update() after. Returns "
          "{'accepted': n, 'duplicate': n}; ValueError naming the first rejected one.")
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
            return statsDict(st);
          },
          "One incremental update over the edges and priors added since the last; returns its "
          "statistics.")
      .def(
          "finalize",
          [](Smoother& s) {
            UpdateStats st;
            {
              py::gil_scoped_release release;
              st = s.finalize();
            }
            return statsDict(st);
          },
          "Relinearises everything and iterates to convergence (the end of a replay).")
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
            py::dict d = runDict(out->run);
            d["ids"] = idsToArray(snapshot.ids);
            d["estimate"] = posesToArray(out->batch);
            return d;
          },
          py::arg("solver") = "lm", py::arg("reseed") = false,
          "A batch refinement of everything updated so far, on request (as `arbor replay "
          "--batch`): lm, or rtr (the certifiable solver, keep-best with LM); with robust options "
          "GNC, before finalize() with every closure free at the c² in use, after it from the "
          "smoother's classification (what it does not hold as settled inliers held out, taken "
          "back within its end's bound), for rtr certifying the inlier problem. reseed: the "
          "winner's estimate becomes the linearisation point when it lowers the cost. Returns "
          "the run's figures (F_* are Σρ when robust), ids and the batch estimate.")
      .def(
          "solve_deferred",
          [](Smoother& s, double budget_mb) {
            UpdateStats st;
            {
              py::gil_scoped_release release;
              st = s.solveDeferred(budget_mb);
            }
            return statsDict(st);
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
          "stats", [](const Smoother& s) { return statsDict(s.stats()); },
          "The online layer's counts and the last update's statistics.")
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
            py::list out;
            for (const ClosureReport& c : s.closures()) {
              py::dict r;
              r["from_id"] = c.from;
              r["to_id"] = c.to;
              r["weight"] = c.weight;
              r["residual"] = c.residual;
              r["status"] = toString(c.status);
              r["graduating"] = c.graduating;
              out.append(r);
            }
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
