// arbor batch FILE: solve a pose graph in batch and print a summary (or one JSON object).
#include <cmath>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <optional>
#include <sstream>

#include <nlohmann/json.hpp>

#include "arbor_slam/core/gnc_solver.h"
#include "arbor_slam/core/initialization.h"
#include "arbor_slam/io/edge_choice_file.h"
#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/io/trajectory_writer.h"
#include "arbor_slam/tools/cli/cli_common.h"
#include "arbor_slam/tools/cli/commands.h"
#include "arbor_slam/tools/cli/covariance_output.h"
#include "arbor_slam/tools/cli/flag_set.h"
#include "arbor_slam/tools/cli/online_threshold.h"
#include "arbor_slam/tools/cli/output_files.h"
#include "arbor_slam/tools/cli/robust_flags.h"
#include "arbor_slam/tools/refine/batch_solvers.h"

namespace arbor::cli {
namespace {

namespace po = boost::program_options;

using refine::BatchSolver;

struct BatchRun {
  std::string file;
  BatchSolver solver = BatchSolver::kLevenbergMarquardt;
  refine::BatchSolveSettings settings;
  std::string init;  // empty: "file" when the file has VERTEX lines, else "odometry"
  std::string output;
  TrajectoryFormat format = TrajectoryFormat::kG2o;  // --format, or -o's extension
  std::string stamps_file;                           // --stamps FILE (io/stamps_file.h)
  std::optional<PoseStamps> stamps;                  // read from it before the solve
  std::string covariances;                           // --covariances
  bool json = false;
  ReadOptions read;
  bool robust = false;
  GncOptions gnc;                 // --kernel, --inlier-threshold, --gnc-inner-start, --gnc-mu-start
  bool online_threshold = false;  // --inlier-threshold online (cli/online_threshold.h)
  std::string rejected_out;       // --rejected-out
  std::string edge_choices;       // --edge-choices FILE (io/edge_choice_file.h)
};

// -o in --format (TUM stamped from --stamps), --covariances: the marginal covariances at the
// final estimate.
template <class G>
void writeOutputs(const BatchRun& run, const PoseGraph<G>& graph, const std::vector<G>& poses) {
  if (!run.output.empty())
    writeEstimateFile(run.output, run.format, graph, poses, run.stamps ? &*run.stamps : nullptr);
  if (!run.covariances.empty()) writeBatchCovariancesFile(run.covariances, graph, poses);
}

// Where the outputs went: text lines, or JSON fields.
void reportOutputs(const BatchRun& run, std::ostream& out) {
  if (!run.output.empty())
    out << "output       " << run.output
        << (run.format == TrajectoryFormat::kG2o ? ""
                                                 : std::string(" (") + toString(run.format) + ")")
        << "\n";
  if (!run.covariances.empty()) out << "covariances  " << run.covariances << "\n";
}
void reportOutputs(const BatchRun& run, nlohmann::json* j) {
  if (!run.output.empty())
    (*j)["output"] = {{"path", run.output}, {"format", toString(run.format)}};
  if (!run.covariances.empty()) (*j)["covariances"] = run.covariances;
}

// arbor batch --solver rtr: the certifiable solver; it starts from its own chordal relaxation
// (F chordal is reported as the start).
template <class G>
int solveCertifiableAndReport(const BatchRun& run, PoseGraph<G>& graph, const ReadReport& report,
                              const Stopwatch& total) {
  std::vector<G> poses = chordalInitialization(graph);
  const double F_initial = objective(graph, poses);
  const refine::BatchSolve solve = refine::runBatchSolver(run.solver, graph, &poses, run.settings);
  const RtrSummary& s = *solve.rtr;
  writeOutputs(run, graph, poses);
  const std::string& termination = solve.termination;
  if (run.json) {
    nlohmann::json j = graphJson(run.file, graph);
    j.update({
        {"solver", refine::toString(run.solver)},
        {"init", "chordal"},
        {"F_initial", F_initial},
        {"F_final", s.F_final},
        {"F_rounded", s.F_rounded},
        {"sesync_objective", s.sesync_objective},
        {"iterations", s.rtr_iterations},
        {"termination", termination},
        {"rank", s.rank},
        {"lambda_min", s.lambda_min},
        {"certified", s.certified},
        {"time_s", s.time_s},
        {"time_phases_s",
         {{"problem", s.time_problem_s},
          {"optimization", s.time_optimization_s},
          {"certificate", s.time_certificate_s},
          {"rounding", s.time_rounding_s},
          {"polish", s.time_polish_s}}},
        {"total_s", total.seconds()},
        {"information_repaired", report.repaired},
        {"information_isotropic", report.made_isotropic},
    });
    reportOutputs(run, &j);
    std::cout << j.dump() << "\n";
    return 0;
  }
  std::cout << std::setprecision(10) << "file         " << graphLine(run.file, graph) << "\n"
            << "solver       " << refine::toString(run.solver) << " ("
            << refine::info(run.solver).description << ")\n"
            << "F chordal    " << F_initial << "\n"
            << "relaxation   " << s.sesync_objective << " (rank " << s.rank << ", λ_min "
            << s.lambda_min << ")\n"
            << "F rounded    " << s.F_rounded << "\n"
            << "F final      " << s.F_final << "\n"
            << "certificate  " << termination << (s.message.empty() ? "" : ": " + s.message) << "\n"
            << std::setprecision(4) << "time         " << s.time_s << " s (problem "
            << s.time_problem_s << ", optimisation " << s.time_optimization_s << ", certificate "
            << s.time_certificate_s << ", rounding " << s.time_rounding_s << ", polish "
            << s.time_polish_s << "), " << total.seconds() << " s total\n";
  reportOutputs(run, std::cout);
  return 0;
}

// gn, lm, dogleg: from --init.
template <class G>
int solveAndReport(const BatchRun& run, PoseGraph<G>& graph, const ReadReport& report,
                   const Stopwatch& total) {
  const InitMethod init = parseInitMethod(
      run.init.empty() ? (graph.has_initial_estimate ? "file" : "odometry") : run.init);
  std::vector<G> poses = initialize(graph, init);
  const refine::BatchSolve solve = refine::runBatchSolver(run.solver, graph, &poses, run.settings);
  const BatchSummary& summary = *solve.local;
  writeOutputs(run, graph, poses);
  const double total_s = total.seconds();

  if (run.json) {
    nlohmann::json j = graphJson(run.file, graph);
    j.update({
        {"solver", refine::toString(run.solver)},
        {"init", toString(init)},
        {"F_initial", summary.F_initial},
        {"F_final", summary.F_final},
        {"iterations", summary.iterations},
        {"termination", toString(summary.termination)},
        {"time_s", summary.time_s},
        {"total_s", total_s},
        {"information_repaired", report.repaired},
        {"information_isotropic", report.made_isotropic},
    });
    reportOutputs(run, &j);
    std::cout << j.dump() << "\n";
  } else {
    std::cout << std::setprecision(10);
    std::cout << "file         " << graphLine(run.file, graph) << "\n";
    if (report.repaired) std::cout << "information  " << report.repaired << " repaired\n";
    if (report.made_isotropic) {
      std::cout << "information  " << report.made_isotropic << " made isotropic\n";
    }
    std::cout << "init         " << toString(init) << "\n"
              << "solver       " << refine::toString(run.solver) << "\n"
              << "F initial    " << summary.F_initial << "\n"
              << "F final      " << summary.F_final << "\n"
              << "iterations   " << summary.iterations << " (" << toString(summary.termination)
              << (summary.message.empty() ? "" : ": " + summary.message) << ")\n"
              << std::setprecision(4) << "time         " << summary.time_s << " s solve, "
              << total_s << " s total\n";
    reportOutputs(run, std::cout);
  }
  return summary.termination == Termination::kDiverged ? 3 : 0;
}

// arbor batch --robust: GNC from --init (core/gnc_solver.h); with --solver rtr, then the
// certifiable solver on the graph without the rejected edges, whose certificate is of that
// inlier problem.
template <class G>
int solveRobustAndReport(const BatchRun& run, PoseGraph<G>& graph, const ReadReport& report,
                         const Stopwatch& total) {
  const bool init_online = run.init == "online";
  const std::string init_name = init_online                  ? "online"
                                : !run.init.empty()          ? run.init
                                : graph.has_initial_estimate ? "file"
                                                             : "odometry";
  std::vector<G> poses =
      init_online ? std::vector<G>() : initialize(graph, parseInitMethod(init_name));
  GncOptions options = run.gnc;
  options.outer.max_iterations = run.settings.max_iterations;
  options.outer.relative_tolerance = run.settings.relative_tolerance;
  options.verbose = run.settings.verbose;
  EdgeChoices choices;
  if (!run.edge_choices.empty()) {  // per-edge trust and kernel (io/edge_choice_file.h)
    choices = readEdgeChoicesFile(run.edge_choices);
    checkEdgeChoices(choices, graph, run.edge_choices);
    applyEdgeChoices(choices, graph, &options);
  }
  std::optional<OnlineThreshold> online;
  GncResult gncFirst;
  int known_outliers = 0, readmitted_online = 0, kept_beyond = 0;
  if (init_online) {  // the replay's classification kept (online_threshold.h solveGncFromReplay)
    OnlineBatch b = solveGncFromReplay(graph, options, choices, run.online_threshold, &poses);
    online = b.online;
    gncFirst = std::move(b.gnc);
    known_outliers = b.known_outliers;
    readmitted_online = b.readmitted;
    kept_beyond = b.kept_beyond;
  } else {
    if (run.online_threshold) {
      online = onlineThreshold(graph, run.gnc.kernel, choices);
      options.threshold = online->c2;
    }
    gncFirst = solveGnc(graph, &poses, options);
  }

  // rtr: the certifiable path on the inlier set (core/gnc_solver.h certifyInliers), which may
  // take rejected edges back; the counts below are after it.
  GncResult gnc = gncFirst;
  // The bound a rejected closure comes back within: from the online replay at its bound, the
  // one the replay's end took closures back within (as readmitFitting, online_threshold.h);
  // else GNC's c².
  const double take_back =
      run.online_threshold && online ? online->c2_take_back : gncFirst.threshold;
  std::optional<CertifiedInliers> certified;
  if (run.solver == BatchSolver::kRtr) {
    RtrOptions rtr = run.settings.rtr;
    rtr.verbose = run.settings.verbose;
    certified = certifyInliers(graph, &gnc, &poses, rtr, /*max_passes=*/5, take_back);
  }
  const double F_all = gnc.F_all, F_inliers = gnc.F_inliers;

  int rejected_loops = 0, loops = 0;
  std::ostringstream rejected;
  for (int k = 0; k < graph.numEdges(); ++k) {
    if (gnc.trusted[k]) continue;
    ++loops;
    if (gnc.inlier[k]) continue;
    ++rejected_loops;
    rejected << graph.ids[graph.edges[k].i] << " " << graph.ids[graph.edges[k].j] << "\n";
  }
  loops += kept_beyond;  // loop closures GNC held as trusted (refine::solveGncFromOnline)
  if (!run.rejected_out.empty()) {
    std::ofstream out(run.rejected_out);
    out << rejected.str();
    if (!out) throw std::runtime_error("cannot write " + run.rejected_out);
  }
  writeOutputs(run, graph, poses);
  const double total_s = total.seconds();
  const char* certificate_scope =
      "the certificate covers the inlier problem (the graph without the rejected edges), not the "
      "choice of inliers";

  if (run.json) {
    nlohmann::json j = graphJson(run.file, graph);
    j.update({
        {"solver", refine::toString(run.solver)},
        {"robust", true},
        {"kernel", toString(run.gnc.kernel)},
        {"init", init_name},
        {"inlier_threshold", gnc.threshold},
        {"variance_factor", gnc.scale},
        {"threshold_rule", run.online_threshold    ? "online"
                           : run.gnc.threshold > 0 ? "given"
                                                   : (run.gnc.estimate_scale ? "auto" : "chi2")},
        {"F_least_squares", gnc.F_least_squares},
        {"F_final", F_all},
        {"F_inliers", F_inliers},
        {"robust_cost", gnc.robust_cost},
        {"loop_closures", loops},
        {"rejected", rejected_loops},
        {"gnc_rounds", gnc.rounds},
        {"gnc_iterations", gnc.iterations},
        {"lm_iterations", gnc.lm_iterations},
        {"gnc_converged", gnc.converged},
        {"gnc_message", gnc.message},
        {"gnc_time_s", gnc.time_s},
        {"total_s", total_s},
        {"information_repaired", report.repaired},
        {"information_isotropic", report.made_isotropic},
    });
    if (init_online) {
      j["known_outliers"] = known_outliers;
      j["readmitted_online"] = readmitted_online;
      j["kept_beyond_online"] = kept_beyond;
    }
    if (online)
      j["online_threshold"] = {{"c2", online->c2},
                               {"c2_in_use", online->c2_in_use},
                               {"c2_take_back", online->c2_take_back},
                               {"noise_scale", online->noise_scale},
                               {"noise_scale_estimated", online->estimated},
                               {"noise_samples", online->samples},
                               {"replay_s", online->replay_s}};
    if (certified) {
      const RtrSummary& r = certified->rtr;
      j.update({{"termination",
                 r.certified ? "certified"
                             : (r.relaxation_solved ? "relaxation_not_exact" : "not_certified")},
                {"readmitted", certified->readmitted},
                {"rtr_passes", certified->passes},
                {"rank", r.rank},
                {"lambda_min", r.lambda_min},
                {"certified", r.certified},
                {"certificate_scope", certificate_scope},
                {"rtr_time_s", r.time_s}});
    }
    if (!run.rejected_out.empty()) j["rejected_out"] = run.rejected_out;
    reportOutputs(run, &j);
    std::cout << j.dump() << "\n";
    return 0;
  }
  std::cout << std::setprecision(10) << "file         " << graphLine(run.file, graph) << "\n";
  if (report.repaired) std::cout << "information  " << report.repaired << " repaired\n";
  if (report.made_isotropic)
    std::cout << "information  " << report.made_isotropic << " made isotropic\n";
  std::cout << "init         " << init_name << "\n"
            << "robust       GNC-" << toString(run.gnc.kernel) << " over "
            << toString(run.gnc.inner.method) << ", c² " << gnc.threshold
            << (run.online_threshold && online
                    ? " (online: the robust replay's, σ̂² " + std::to_string(online->noise_scale) +
                          (online->estimated ? "" : ", no estimate") + ", " +
                          std::to_string(online->replay_s) + " s)"
                : run.gnc.threshold > 0 ? std::string(" (given)")
                : run.gnc.estimate_scale
                    ? " (χ² " + std::to_string(run.gnc.confidence) + " quantile × σ̂² " +
                          std::to_string(gnc.scale) + ")"
                    : " (χ² " + std::to_string(run.gnc.confidence) + " quantile)")
            << "\n"
            << "F least sq.  " << gnc.F_least_squares << " (every edge, weight 1)\n"
            << "F final      " << F_all << " (every edge)\n"
            << "F inliers    " << F_inliers << " (without the rejected edges)\n"
            << "rejected     " << rejected_loops << " of " << loops << " loop closures ("
            << graph.numEdges() - loops << " odometry edges trusted)\n"
            << "gnc          " << gnc.rounds << " round(s), " << gnc.iterations << " steps, "
            << gnc.lm_iterations << " LM iterations (" << gnc.message << ")\n";
  if (init_online)
    std::cout << "online       " << known_outliers
              << " closure(s) the replay rejected held out of GNC, " << readmitted_online
              << " taken back (fit within c² " << take_back
              << (run.online_threshold ? ", the replay's end's bound), " : ", GNC's), ")
              << kept_beyond << " it kept beyond GNC's c² held\n";
  if (certified) {
    const RtrSummary& r = certified->rtr;
    std::cout << "readmitted   " << certified->readmitted
              << " rejected edge(s) fit at the certified optimum (" << certified->passes
              << " staircase run(s))\n"
              << "certificate  "
              << (r.certified ? "certified"
                              : (r.relaxation_solved ? "relaxation_not_exact" : "not_certified"))
              << (r.message.empty() ? "" : ": " + r.message) << " (rank " << r.rank << ", λ_min "
              << r.lambda_min << "); " << certificate_scope << "\n";
  }
  std::cout << std::setprecision(4) << "time         " << gnc.time_s << " s GNC"
            << (certified ? ", " + std::to_string(certified->rtr.time_s) + " s RTR" : "") << ", "
            << total_s << " s total\n";
  if (!run.rejected_out.empty()) std::cout << "rejected out " << run.rejected_out << "\n";
  reportOutputs(run, std::cout);
  return 0;
}

// "lm | gn | dogleg | rtr", then one line per row of the table.
std::string solverHelp() {
  std::string help = refine::batchSolverNames();
  for (const refine::BatchSolverInfo& row : refine::batchSolvers()) {
    help += std::string("\n  ") + row.name + ": " + row.description;
  }
  return help;
}

}  // namespace

int batchCommand(const std::vector<std::string>& args) {
  Stopwatch total;
  BatchRun run;
  std::string solver = refine::toString(run.solver), information = "refuse";
  std::string format, inner_start = "initial", mu_start = "initial";
  FlagSet flags("arbor batch FILE [options]   (FILE: g2o or TORO)",
                {"arbor batch data/sphere_3d.g2o --solver rtr --json",
                 "arbor batch data/manhattan_2d_group_0.1.g2o --robust -o estimate.g2o"});
  flags.positional("file", po::value(&run.file)->required());
  const char* const solve = "Solve";
  flags.add(Tier::kCommon, solve)("solver", po::value(&solver)->default_value(solver),
                                  solverHelp().c_str())(
      "init", po::value(&run.init),
      "odometry | spanning-tree | chordal | file (default: file if it has VERTEX lines, else "
      "odometry; rtr starts from its own chordal relaxation); with --robust also online, its "
      "default: the estimate of the robust online replay (arbor replay --robust), whose rejected "
      "closures GNC holds out and takes back only where they fit at the replay's bound");
  flags.add(Tier::kAdvanced, solve)("max-iterations",
                                    po::value(&run.settings.max_iterations)->default_value(100),
                                    "iteration limit (gn, lm, dogleg)")(
      "rel-tol", po::value(&run.settings.relative_tolerance)->default_value(1e-5, "1e-05"),
      "stop when the relative decrease of F is below this (gn, lm, dogleg)")(
      "verbose,v", po::bool_switch(&run.settings.verbose), "per-iteration log on stderr");
  const char* const io = "Input and output";
  flags.add(Tier::kCommon, io)("output,o", po::value(&run.output)->value_name("OUT"),
                               "write the estimate (as --format)")(
      "format", po::value(&format)->value_name("g2o|tum|kitti"), kOutputFormatHelp)(
      "json", po::bool_switch(&run.json), "print one JSON object");
  flags.add(Tier::kAdvanced, io)(
      "information", po::value(&information)->default_value("refuse"),
      "what to do with information matrices that are not positive definite: refuse | repair | "
      "isotropic")("stamps", po::value(&run.stamps_file), kStampsHelp)(
      "covariances", po::value(&run.covariances),
      "write every pose's marginal covariance at the final estimate, `id` and the upper triangle "
      "a line (docs/files.md)");
  addRobustFlags(flags,
                 "robust to false loop closures: GNC over LM (Yang et al. 2020), odometry (|i-j| "
                 "= 1) trusted, by default from the robust online replay's estimate, "
                 "classification and threshold (--init online, --inlier-threshold online; "
                 "GTSAM's GncOptimizer: --init file --inlier-threshold chi2); with --solver rtr, "
                 "then the certifiable solver on the edges kept",
                 "online");
  flags.add(Tier::kAdvanced, kRobustSection, "robust")(
      "edge-choices", po::value(&run.edge_choices),
      "with --robust: per-edge trust and kernel, \"FROM TO TRUST [KERNEL]\" a line "
      "(docs/files.md); the default trust is the batch's rule (odometry |i-j| = 1 trusted)");
  flags.add(Tier::kExperimental, kRobustSection, "robust")(
      "gnc-inner-start", po::value(&inner_start)->default_value(inner_start),
      "with --robust: each GNC step's weighted solve starts from the initial estimate (initial, "
      "as GTSAM's GncOptimizer) or from the previous step's (previous)")(
      "gnc-mu-start", po::value(&mu_start)->default_value(mu_start),
      "with --robust: GNC's first μ from the residuals at the initial estimate (initial, as "
      "GTSAM) or at the least-squares solution (least-squares)");
  const std::optional<po::variables_map> parsed = flags.parse(args);
  if (!parsed) return 0;
  const po::variables_map& given = *parsed;
  try {
    run.solver = refine::parseBatchSolver(solver, "--solver");
    if (!run.init.empty() && run.init != "online") parseInitMethod(run.init);
  } catch (const std::invalid_argument& e) {
    throw UsageError(e.what());
  }
  if (run.settings.max_iterations < 0) throw UsageError("--max-iterations must be >= 0");
  const RobustFlags robust = readRobustFlags(given, /*allow_auto=*/true);
  if (run.init == "online" && !robust.robust)
    throw UsageError("--init online needs --robust (it is the robust online replay's estimate)");
  run.robust = robust.robust;
  if (run.robust && run.init.empty()) run.init = "online";
  run.gnc.kernel = robust.kernel;
  run.gnc.threshold = robust.threshold;
  run.gnc.estimate_scale = robust.estimate_scale;
  run.online_threshold = robust.online_threshold;
  run.rejected_out = robust.rejected_out;
  if (run.robust && run.solver != BatchSolver::kLevenbergMarquardt &&
      run.solver != BatchSolver::kRtr)
    throw UsageError(
        "--robust runs GNC over LM, then optionally rtr: --solver must be lm or "
        "rtr, not '" +
        solver + "'");
  if (run.robust) {
    if (inner_start != "initial" && inner_start != "previous")
      throw UsageError("--gnc-inner-start must be initial or previous, not '" + inner_start + "'");
    run.gnc.inner_start =
        inner_start == "initial" ? GncInnerStart::kInitial : GncInnerStart::kPrevious;
    if (mu_start != "initial" && mu_start != "least-squares")
      throw UsageError("--gnc-mu-start must be initial or least-squares, not '" + mu_start + "'");
    run.gnc.mu_start = mu_start == "initial" ? GncMuStart::kInitial : GncMuStart::kLeastSquares;
  } else {
    for (const char* flag : {"gnc-inner-start", "gnc-mu-start", "edge-choices"})
      if (given.count(flag) && !given[flag].defaulted())
        throw UsageError(std::string("--") + flag + " needs --robust");
  }
  if (!(run.settings.relative_tolerance >= 0)) throw UsageError("--rel-tol must be >= 0");
  if (!format.empty() && run.output.empty()) throw UsageError("--format needs --output");
  run.format = outputFormat(run.output, format);
  requireTumForStamps(run.stamps_file, run.format);
  run.read.information = parseInformationPolicy(information);
  requireWritable("--output", run.output);
  requireWritable("--covariances", run.covariances);
  requireWritable("--rejected-out", run.rejected_out);

  ReadReport report;
  AnyPoseGraph any = readGraphFile(run.file, run.read, &report);
  if (!run.stamps_file.empty()) run.stamps = readStampsOf(run.stamps_file, any);
  return std::visit(
      [&](auto& graph) {
        if (run.robust) return solveRobustAndReport(run, graph, report, total);
        return refine::info(run.solver).certifies
                   ? solveCertifiableAndReport(run, graph, report, total)
                   : solveAndReport(run, graph, report, total);
      },
      any);
}

}  // namespace arbor::cli
