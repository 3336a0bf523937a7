// arbor replay FILE: feed a file's edges one at a time (in order of max(i, j), then file order)
// to the incremental smoother, print per-update latency, final F, and F of batch LM started
// from the incremental estimate.
#include "arbor_slam/tools/cli/replay_command.h"

#include <algorithm>
#include <cctype>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "arbor_slam/core/gnc_solver.h"
#include "arbor_slam/core/heap_policy.h"
#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/tools/cli/batch_refinement.h"
#include "arbor_slam/tools/cli/cli_common.h"
#include "arbor_slam/tools/cli/commands.h"
#include "arbor_slam/tools/cli/covariance_output.h"
#include "arbor_slam/tools/cli/flag_set.h"
#include "arbor_slam/tools/cli/output_files.h"
#include "arbor_slam/tools/cli/replay_runner.h"
#include "arbor_slam/tools/cli/smoother_flags.h"

namespace arbor::cli {
namespace {

namespace po = boost::program_options;

using ReplayRun = ReplayCommandLine;

// "F batch LM    ": the final batch is the --batch solver's, LM without it.
std::string batchLabel(const ReplayRun& run) {
  std::string name = refine::toString(run.batch.value_or(refine::BatchSolver::kLevenbergMarquardt));
  for (char& c : name) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  name.resize(std::max<size_t>(name.size() + 1, 6), ' ');
  return "F batch " + name;
}

template <class G>
int replay(const ReplayRun& run, PoseGraph<G>& graph, const std::optional<PoseStamps>& stamps,
           const Stopwatch& total_clock) {
  ReplaySettings settings;
  settings.smoother = run.smoother;
  settings.per_pose = run.step == "pose";
  settings.first_update_edges = run.first_update_edges;
  settings.initial_from_file = run.initial == "file";
  if (settings.initial_from_file && !graph.has_initial_estimate) {
    std::cerr << "arbor replay: --initial file needs the file's VERTEX lines; " << run.file
              << " has none\n";
    return 2;
  }
  settings.finalize = run.finalize;
  settings.covariances = !run.covariances.empty();
  if (run.robust.robust) {
    RobustOptions robust = run.online;
    robust.kernel = run.robust.kernel;
    robust.threshold = run.robust.threshold;
    settings.robust = robust;
  }
  if (!run.edge_choices.empty()) {
    settings.choices = readEdgeChoicesFile(run.edge_choices);
    checkEdgeChoices(settings.choices, graph, run.edge_choices);
  }
  LoopResult<G> loop_result;
  const bool with_batches = run.batch.has_value();
  if (with_batches) {
    BatchLoopSettings loop;
    loop.solver = *run.batch;
    loop.every = run.batch_every;
    loop.reseed = run.reseed;
    loop.synchronous = run.batch_sync;
    loop_result = runReplayWithBatches(graph, settings, loop);
  } else {
    loop_result.replay = runReplay(graph, settings);
  }
  const ReplayResult<G>& r = loop_result.replay;
  for (const auto& line : r.rejections) std::cerr << "arbor replay: " << line << "\n";
  if (!run.output.empty())
    writeEstimateFile(run.output, run.format, graph, r.poses, stamps ? &*stamps : nullptr);
  if (!run.covariances.empty())
    writeCovariancesFile<G::kDoF>(run.covariances, r.covariance_ids, r.covariances);
  if (!run.latency_csv.empty()) writeLatencyCsv(run.latency_csv, r.rows);
  const double gap = (r.F_final - r.batch.F_final) / r.batch.F_final;
  const LatencySummary& lat = r.latency;
  const OnlineStats& online = r.online;
  if (!run.robust.rejected_out.empty()) {
    std::ofstream out(run.robust.rejected_out);
    for (const ClosureReport& c : r.closures)
      if (c.status == ClosureStatus::kOutlier) out << c.from << " " << c.to << "\n";
    if (!out) throw std::runtime_error("cannot write " + run.robust.rejected_out);
  }
  const double F_kept =
      run.robust.robust ? objective(keepEdges(graph, keptEdges(graph, r.closures)), r.poses) : 0;
  const double c2 =
      run.robust.threshold > 0 ? run.robust.threshold : chiSquareThreshold(0.99, G::kDoF);

  if (run.json) {
    nlohmann::json j = graphJson(run.file, graph);
    j.update({
        {"step", run.step},
        {"updates", static_cast<int>(r.rows.size())},
        {"total_s", r.total_s},
        {"update_s", r.update_s},
        {"first_update_edges", run.first_update_edges},
        {"initial", run.initial},
        {"first_update_s", r.first_update_s},
        {"finalize_s", r.finalize_s},
        {"latency_ms", {{"p50", lat.p50}, {"p90", lat.p90}, {"p99", lat.p99}, {"max", lat.max}}},
        {"p99_first_tenth_ms", r.tenths.first.p99},
        {"p99_last_tenth_ms", r.tenths.last.p99},
        {"F_incremental", r.F_incremental},
        {"deferred_at_end", r.deferred_at_end},
        {"F_drained", r.F_drained},
        {"F_final", r.F_final},
        {"F_batch", r.batch.F_final},
        {"batch_time_s", r.batch.time_s},
        {"batch_iterations", r.batch.iterations},
        {"relative_gap", gap},
        {"relinearized_total", r.relinearized},
        {"indeterminate_cliques", r.indeterminate},
        {"duplicates", r.duplicates},
        {"rejected", r.rejected},
        {"pending", r.pending},
        {"peak_rss_mb", peakRssMb()},
        {"bounded_heap", run.bounded_heap},
        {"peak_rss_mb_updates", r.rows.empty() ? 0.0 : r.rows.back().peak_rss_kb / 1024.0},
        {"wall_s", total_clock.seconds()},
    });
    if (run.robust.robust) {
      j["robust"] = {
          {"kernel", toString(run.robust.kernel)},
          {"inlier_threshold", c2},
          {"entry", toString(run.online.entry)},
          {"noise_scale_mode", toString(run.online.scale)},
          {"corroboration_window", run.online.corroboration_window},
          {"finalize_rounds", run.online.finalize_rounds},
          {"rules_off", run.online.rules_off.toString()},
          {"threshold_in_use", online.closure_threshold},
          {"threshold_at_end", online.closure_threshold_at_end},
          {"noise_scale", online.noise_scale},
          {"noise_scale_estimated", online.noise_scale_estimated},
          {"noise_samples", online.noise_samples},
          {"F_kept", F_kept},
          {"closures_inlier", online.closures_inlier},
          {"closures_outlier", online.closures_outlier},
          {"closures_trusted", online.closures_trusted},
          {"closures_graduating", online.closures_graduating},
          {"graduation_steps", online.graduation_steps},
          {"graduation_updates", online.graduation_updates},
          {"closures_unconfirmed", online.closures_unconfirmed},
          {"closures_kept_at_word", online.closures_kept_at_word},
          {"rechecks_bounded", online.rechecks_bounded},
          {"warm_up_relinearizations", online.warm_up_relinearizations},
      };
      if (!run.robust.rejected_out.empty()) j["rejected_out"] = run.robust.rejected_out;
    }
    if (!run.output.empty()) j["output"] = {{"path", run.output}, {"format", toString(run.format)}};
    if (!run.covariances.empty()) j["covariances"] = run.covariances;
    if (with_batches) {
      j["batch"] = refine::toString(*run.batch);
      j["batch_every"] = run.batch_every;
      j["reseed"] = run.reseed;
      j["batch_sync"] = run.batch_sync;
      j["batches_skipped"] = loop_result.skipped;
      j["reseeds"] = loop_result.reseeds;
      j["reseed_s"] = loop_result.reseed_s;
      j["batches"] = nlohmann::json::array();
      for (const BatchRun& b : loop_result.batches) j["batches"].push_back(batchRunJson(b));
    }
    std::cout << j.dump() << "\n";
    return 0;
  }
  std::cout << std::setprecision(10) << "file          " << graphLine(run.file, graph) << "\n"
            << "updates       " << r.rows.size() << " (one per " << run.step << ")\n"
            << std::setprecision(4) << "total         " << r.total_s << " s (updates " << r.update_s
            << " s, final relinearisation " << r.finalize_s << " s)\n";
  if (run.first_update_edges > 0)
    std::cout << "first update  " << r.rows.front().edges_so_far << " edges in " << r.first_update_s
              << " s (the latency below is of the updates after it)\n";
  std::cout << "latency ms    p50 " << lat.p50 << "  p90 " << lat.p90 << "  p99 " << lat.p99
            << "  max " << lat.max << "\n"
            << "p99 tenths    first " << r.tenths.first.p99 << "  last " << r.tenths.last.p99
            << " (ms, of the first and the last tenth of the updates)\n"
            << std::setprecision(10) << "F incremental " << r.F_incremental
            << " (before the final relinearisation)\n";
  if (r.deferred_at_end > 0)
    std::cout << "F drained     " << r.F_drained << " (" << r.deferred_at_end
              << " deferred cliques solved)\n";
  std::cout << "F final       " << r.F_final << "\n"
            << batchLabel(run) << r.batch.F_final << " (" << r.batch.iterations
            << " iterations from the incremental estimate"
            << (run.robust.robust ? ", kept edges" : "") << ", " << std::setprecision(4)
            << r.batch.time_s << " s)\n"
            << "gap           " << std::setprecision(3) << 100.0 * gap << " %\n"
            << "relinearized  " << r.relinearized << " variables in total\n";
  if (run.robust.robust) {
    std::cout << std::setprecision(4) << "robust        GNC-" << toString(run.robust.kernel)
              << " per loop closure, online, c² " << c2
              << (run.robust.threshold > 0 ? " (given)" : " (χ² 0.99 quantile)") << "\n"
              << "entry         " << toString(run.online.entry) << " test; noise scale "
              << toString(run.online.scale) << ": σ̂² " << online.noise_scale << " from "
              << online.noise_samples << " innovations, c² in use " << online.closure_threshold
              << "\n"
              << "closures      " << online.closures_inlier << " inlier, "
              << online.closures_outlier << " outlier (rejected), " << online.closures_trusted
              << " trusted, " << online.closures_graduating << " still graduating; "
              << online.graduation_steps << " graduation steps, " << online.graduation_updates
              << " extra updates, " << online.closures_unconfirmed
              << " inliers dropped by their leave-one-out innovation, "
              << online.closures_kept_at_word << " kept at Ω's word\n"
              << std::setprecision(10) << "F kept        " << F_kept
              << " (the final estimate without the rejected edges)\n";
    if (!run.robust.rejected_out.empty())
      std::cout << "rejected out  " << run.robust.rejected_out << "\n";
  }
  if (r.indeterminate) std::cout << "indeterminate " << r.indeterminate << " cliques damped\n";
  if (r.duplicates || r.rejected || r.pending) {
    std::cout << "input         " << r.duplicates << " duplicates, " << r.rejected << " rejected, "
              << r.pending << " never connected\n";
  }
  if (with_batches) {
    std::cout << "batch runs    " << loop_result.batches.size() << " ("
              << refine::toString(*run.batch) << ", " << loop_result.skipped << " skipped, "
              << loop_result.reseeds << " reseeds, " << std::setprecision(4) << loop_result.reseed_s
              << " s rebuilding)\n";
    for (const BatchRun& b : loop_result.batches) std::cout << "  " << batchRunLine(b) << "\n";
  }
  if (!run.output.empty())
    std::cout << "output        " << run.output << " (" << toString(run.format) << ")\n";
  if (!run.covariances.empty()) std::cout << "covariances   " << run.covariances << "\n";
  std::cout << "peak RSS      " << peakRssMb() << " MiB ("
            << (r.rows.empty() ? 0.0 : r.rows.back().peak_rss_kb / 1024.0)
            << " MiB after the last update, before the final pass and the batch)\n";
  return 0;
}

}  // namespace

namespace {

// What the flags are read into before the checks turn them into a ReplayCommandLine.
struct ReplayFlagValues {
  ReplayCommandLine run;
  std::string information = "refuse", batch, format;
  bool no_finalize = false;
};

const char* const kInput = "Input and output";
const char* const kBatch = "Batch refinement";

// Every flag of `arbor replay`, bound to `v`; each is declared here or in its table only.
FlagSet replayFlagSet(ReplayFlagValues& v) {
  ReplayCommandLine& run = v.run;
  FlagSet flags("arbor replay FILE [options]   (FILE: g2o or TORO)",
                {"arbor replay data/manhattan_2d.g2o --json",
                 "arbor replay data/sphere_3d_random_0.1.g2o --robust -o estimate.g2o"});
  flags.positional("file", po::value(&run.file)->required());
  flags.add(Tier::kCommon, kInput)(
      "step", po::value(&run.step)->default_value("edge")->value_name("edge|pose"),
      "edge: update after every edge; pose: once per new pose with all its edges")(
      "output,o", po::value(&run.output)->value_name("OUT"),
      "write the final estimate (as --format)")(
      "format", po::value(&v.format)->value_name("g2o|tum|kitti"), kOutputFormatHelp)(
      "json", po::bool_switch(&run.json), "print one JSON object");
  flags.add(Tier::kAdvanced, kInput)(
      "first-update-edges", po::value(&run.first_update_edges)->default_value(0),
      "the first N edges (whole --step groups) in one update, a map loaded before the rest "
      "streams in; the latency figures are then of the updates after it (0: off)")(
      "initial", po::value(&run.initial)->default_value("odometry"),
      "where a new pose starts: odometry (the pose its first edge comes from, composed with "
      "it) | file (its VERTEX line: a saved map starts at its estimate)")(
      "no-finalize", po::bool_switch(&v.no_finalize),
      "skip the final relinearise-all pass (report the raw incremental estimate)")(
      "information", po::value(&v.information)->default_value("refuse"),
      "refuse | repair | isotropic (information matrices that are not positive definite)")(
      "stamps", po::value(&run.stamps_file), kStampsHelp)(
      "covariances", po::value(&run.covariances),
      "write every pose's marginal covariance from the final Bayes tree, `id` and the upper "
      "triangle a line (docs/files.md)")("latency-csv", po::value(&run.latency_csv),
                                         "one row per update")(
      "bounded-heap", po::bool_switch(&run.bounded_heap),
      "return freed clique storage to the system: glibc's mmap threshold fixed at 1 MiB "
      "(core/heap_policy.h). Lowers the peak of very large graphs; costs page faults where "
      "large tops are re-eliminated every update (docs/design.md, \"Memory\")");
  flags.add(smootherOptionTable());
  flags.add(Tier::kCommon, kBatch)(
      "batch", po::value(&v.batch)->value_name("SOLVER"),
      (refine::batchSolverNames(true) + ": batch runs in the loop and after finalize").c_str())(
      "batch-every", po::value(&run.batch_every)->default_value(0)->value_name("N"),
      "a background batch run every N updates (needs --batch)");
  flags.add(Tier::kAdvanced, kBatch)("reseed", po::bool_switch(&run.reseed),
                                     "rebuild the smoother from a batch estimate with lower F");
  flags.add(Tier::kExperimental, kBatch)(
      "batch-sync", po::bool_switch(&run.batch_sync),
      "run each batch on the replay thread at its snapshot, blocking (not in the updates' "
      "latency): the same batches and reseeds on any machine, for reproducible comparisons");
  addRobustFlags(flags,
                 "robust to false loop closures: graduated non-convexity per loop closure in "
                 "the Bayes tree (riSAM-style), odometry (|i-j| = 1) trusted; the final batch "
                 "LM runs over the edges kept");
  flags.add(Tier::kAdvanced, kRobustSection, "robust")(
      "edge-choices", po::value(&run.edge_choices),
      "with --robust: per-edge trust and kernel, 'FROM TO default|trusted|robust [KERNEL]' a line "
      "(docs/files.md)");
  flags.add(onlineRobustOptionTable());
  return flags;
}

}  // namespace

std::vector<FlagInfo> replayFlags() {
  ReplayFlagValues v;
  return replayFlagSet(v).flags();
}

std::optional<ReplayCommandLine> parseReplayCommandLine(const std::vector<std::string>& args) {
  ReplayFlagValues v;
  const FlagSet flags = replayFlagSet(v);
  const std::optional<po::variables_map> parsed = flags.parse(args);
  if (!parsed) return std::nullopt;
  const po::variables_map& vm = *parsed;
  ReplayCommandLine& run = v.run;
  const std::string &information = v.information, &batch = v.batch, &format = v.format;
  const bool no_finalize = v.no_finalize;
  if (run.step != "edge" && run.step != "pose") {
    throw UsageError("--step must be edge or pose, not '" + run.step + "'");
  }
  run.smoother = readSmootherFlags(vm);
  run.finalize = !no_finalize;
  if (!batch.empty()) {
    try {
      run.batch = refine::parseBatchSolver(batch, "--batch", /*refinement_only=*/true);
    } catch (const std::invalid_argument& e) {
      throw UsageError(e.what());
    }
  }
  if (run.initial != "odometry" && run.initial != "file")
    throw UsageError("--initial must be odometry or file, not '" + run.initial + "'");
  if (run.first_update_edges < 0) {
    throw UsageError("--first-update-edges must be >= 0, not '" +
                     std::to_string(run.first_update_edges) + "'");
  }
  if (run.batch_every < 0) {
    throw UsageError("--batch-every must be >= 0, not '" + std::to_string(run.batch_every) + "'");
  }
  if (!run.batch && (run.batch_every > 0 || run.reseed || run.batch_sync)) {
    throw UsageError("--batch-every, --reseed and --batch-sync need --batch " +
                     refine::batchSolverNames(true, "|"));
  }
  run.robust = readRobustFlags(vm, /*allow_auto=*/false);
  if (!run.edge_choices.empty() && !run.robust.robust)
    throw UsageError("--edge-choices needs --robust");
  readOnlineRobustFlags(vm, run.robust.robust, &run.online);
  requireInlineWithRobust(run.robust.robust, run.smoother);
  if (!format.empty() && run.output.empty()) throw UsageError("--format needs --output");
  run.format = outputFormat(run.output, format);
  requireTumForStamps(run.stamps_file, run.format);
  run.read.information = parseInformationPolicy(information);
  return std::move(run);
}

int replayCommand(const std::vector<std::string>& args) {
  Stopwatch total;
  const std::optional<ReplayCommandLine> run = parseReplayCommandLine(args);
  if (!run) return 0;
  requireWritable("--output", run->output);
  requireWritable("--covariances", run->covariances);
  requireWritable("--latency-csv", run->latency_csv);
  requireWritable("--rejected-out", run->robust.rejected_out);
  if (run->bounded_heap) useBoundedHeap();
  AnyPoseGraph any = readGraphFile(run->file, run->read);
  std::optional<PoseStamps> stamps;
  if (!run->stamps_file.empty()) stamps = readStampsOf(run->stamps_file, any);
  return std::visit([&](auto& graph) { return replay(*run, graph, stamps, total); }, any);
}

}  // namespace arbor::cli
