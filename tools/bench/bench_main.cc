// arbor-bench: benchmarks on the shared datasets (run as `arbor bench ...`).
//   arbor-bench batch [--shared DIR] [--only NAME,...] [--repeat N] [--no-ceres]
//     LM from a spanning-tree start for Arbor and for Ceres (the paper's settings), a Markdown
//     table like the paper's Table II on stdout.
//   arbor-bench replay [--shared DIR] [--only NAME,...] [--csv-dir DIR] [--step edge|pose]
//                      [smoother flags]
//     edge-by-edge (or pose-by-pose) replay through the incremental smoother beside GTSAM
//     iSAM2's figures fed the same way.
//   arbor-bench paper [--shared DIR] [--only NAME,...] [--out-dir DIR] [--markdown FILE] [--plots]
//     every solver (replay, LM, GN, dogleg, RTR, Ceres) on every shared dataset with the settings
//     of the paper's Table II; estimates, latency CSVs, results.tsv/json and a Markdown report.
//   arbor-bench micro [--sizes=N,...] [--benchmark_* flags]
//     the Google Benchmark microbenchmarks: runs `arbor-microbench` built beside this program.
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>

#include <boost/program_options.hpp>

#include "arbor/core/blas_threads.h"
#include "arbor/core/initialization.h"
#include "arbor/io/pose_graph_file.h"
#include "arbor/tools/bench/ceres_pose_graph.h"
#include "arbor/tools/bench/format.h"
#include "arbor/tools/bench/growth.h"
#include "arbor/tools/bench/paper_runner.h"
#include "arbor/tools/bench/shared_data.h"
#include "arbor/tools/cli/cli_common.h"
#include "arbor/tools/cli/replay_runner.h"
#include "arbor/tools/cli/smoother_flags.h"
#include "arbor/tools/refine/batch_solvers.h"

namespace {

namespace po = boost::program_options;
using namespace arbor;

using bench::fmt;

struct Row {
  double time = 1e300;
  int iterations = 0;
  double F = 0;
  std::string termination;
};

template <class G>
void benchBatch(const std::string& name, const PoseGraph<G>& graph, const bench::Reference* ref,
                int repeat, bool ceres, const std::string& note) {
  const std::vector<G> start = spanningTreeInitialization(graph);
  Row ours, theirs;
  for (int r = 0; r < repeat; ++r) {
    std::vector<G> poses = start;
    const refine::BatchSolve s =
        refine::runBatchSolver(refine::BatchSolver::kLevenbergMarquardt, graph, &poses);
    if (s.time_s < ours.time) ours = {s.time_s, s.iterations, s.F_final, s.termination};
    if (ceres) {
      std::vector<G> cposes = start;
      const bench::CeresResult c = bench::solveWithCeres(graph, &cposes);
      if (c.time_s < theirs.time) theirs = {c.time_s, c.iterations, c.F_final, c.termination};
    }
  }
  std::cout << "| " << name << note << " | " << G::kDim << " | " << graph.numPoses() << " | "
            << graph.numEdges() << " | " << (ref ? fmt("%.6e", ref->F_star) : "—") << " | "
            << fmt("%.3f", ours.time) << " | " << ours.iterations << " | " << fmt("%.6e", ours.F)
            << " | " << ours.termination << " | ";
  if (ceres) {
    std::cout << fmt("%.3f", theirs.time) << " | " << theirs.iterations << " | "
              << fmt("%.6e", theirs.F) << " | " << theirs.termination << " | "
              << fmt("%.2f", ours.time / theirs.time) << " |";
  } else {
    std::cout << "— | — | — | — | — |";
  }
  std::cout << std::endl;
}

template <class G>
void benchReplay(const std::string& name, const PoseGraph<G>& graph, const bench::Reference* ref,
                 const bench::Anchor* gtsam, const std::string& csv_dir, const std::string& note,
                 const cli::ReplaySettings& settings) {
  const cli::ReplayResult<G> r = cli::runReplay(graph, settings);
  if (!csv_dir.empty()) cli::writeLatencyCsv(csv_dir + "/" + name + ".csv", r.rows);
  const auto& l = r.latency;
  std::cout << "| " << name << note << " | " << graph.numEdges() << " | " << fmt("%.4g", r.total_s)
            << " | " << fmt("%.3g", r.finalize_s) << " | " << fmt("%.3f", l.p50) << " | "
            << fmt("%.3f", l.p99) << " | " << fmt("%.2f", l.max) << " | " << fmt("%.6e", r.F_final)
            << " | "
            << (ref ? fmt("%+.3f%%", 100.0 * (r.F_final - ref->F_star) / ref->F_star) : "—")
            << " | " << fmt("%.3f", r.batch.time_s) << " | " << fmt("%.6e", r.batch.F_final)
            << " | ";
  if (gtsam) {
    std::cout << fmt("%.4g", gtsam->total_s) << " | " << fmt("%.2f", gtsam->p99_ms) << " | "
              << fmt("%.6e", gtsam->F) << " | " << fmt("%.2f", r.total_s / gtsam->total_s) << " | "
              << fmt("%.2f", r.update_s / gtsam->total_s) << " | "
              << fmt("%.2f", l.p99 / gtsam->p99_ms) << " |";
  } else {
    std::cout << "aborted | — | — | — | — | — |";
  }
  if (r.indeterminate) std::cout << " " << r.indeterminate << " cliques damped";
  std::cout << std::endl;
}

// The options every dataset benchmark takes (--help, --shared, --only), in this order; the
// caller adds its own after them.
struct DatasetOptions {
  std::string shared, only;
};

po::options_description datasetOptions(const std::string& caption, DatasetOptions* data,
                                       const std::string& default_shared) {
  po::options_description options(caption);
  options.add_options()("help,h", "show this help")(
      "shared", po::value(&data->shared)->default_value(bench::sharedDirectory(default_shared)),
      "the shared folder (datasets/, reference/)")("only", po::value(&data->only),
                                                   "comma-separated dataset names");
  return options;
}

// Parses `args` into the variables bound to `options` (and into *vm when given); false (after
// printing the help) on --help. Throws cli::UsageError (exit 2) on a bad command line.
bool parseOptions(const std::vector<std::string>& args, const po::options_description& options,
                  po::variables_map* vm = nullptr) {
  if (cli::helpRequested(args, options)) return false;
  po::variables_map parsed =
      cli::parseArguments(args, options, po::positional_options_description());
  if (vm) *vm = std::move(parsed);
  return true;
}

// --step edge|pose: whether each update takes a pose with all its edges.
bool perPose(const std::string& step) {
  if (step != "edge" && step != "pose")
    throw cli::UsageError("--step must be edge or pose, not '" + step + "'");
  return step == "pose";
}

int replay(const std::vector<std::string>& args, const std::string& default_shared) {
  DatasetOptions data;
  std::string csv_dir, step;
  po::options_description options =
      datasetOptions("arbor bench replay [options]", &data, default_shared);
  options.add_options()("csv-dir", po::value(&csv_dir),
                        "write per-update latency CSVs (NAME.csv) here")(
      "step", po::value(&step)->default_value("edge"),
      "edge: an update per edge (against GTSAM's isam2_edge rows); pose: per new pose with its "
      "edges (against isam2_pose)");
  cli::addSmootherFlags(options);
  po::variables_map vm;
  if (!parseOptions(args, options, &vm)) return 0;
  cli::ReplaySettings settings;
  settings.smoother = cli::readSmootherFlags(vm);
  settings.per_pose = perPose(step);
  const bool per_pose = settings.per_pose;
  const auto files = bench::selectDatasets(data.shared, data.only);
  const auto refs = bench::readOptimumTable(data.shared);
  const auto anchors = bench::readAnchorTable(data.shared);
  std::cout << (per_pose ? "Pose-by-pose" : "Edge-by-edge") << " replay ("
            << cli::describeSmoother(settings.smoother)
            << ", final relinearise-all pass), then batch LM from its estimate. GTSAM: iSAM2 "
            << (per_pose ? "per pose" : "per edge")
            << " from reference/anchors.tsv (update() only; its back-substitution is deferred, "
               "and it has no final pass). total = our updates + the final pass; updates/GTSAM "
               "leaves the final pass out, as GTSAM's figure does.\n\n"
            << "| dataset | edges | total s | final pass s | p50 ms | p99 ms | max ms | F_final | "
               "vs F* | LM s | LM F | GTSAM s | GTSAM p99 | GTSAM F | total/GTSAM | "
               "updates/GTSAM | p99/GTSAM |\n"
            << "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  bench::forEachDataset(files, [&](const bench::LoadedDataset& d) {
    const auto ref = refs.find(d.name);
    // A GTSAM row that did not end "ok" (it aborted) counts as missing.
    const auto gtsam = anchors.find({d.name, per_pose ? "isam2_pose" : "isam2_edge"});
    const bool gtsam_ok = gtsam != anchors.end() && gtsam->second.status == "ok";
    std::visit(
        [&](const auto& g) {
          benchReplay(d.name, g, ref == refs.end() ? nullptr : &ref->second,
                      gtsam_ok ? &gtsam->second : nullptr, csv_dir, d.note, settings);
        },
        d.graph);
  });
  return 0;
}

int batch(const std::vector<std::string>& args, const std::string& default_shared) {
  DatasetOptions data;
  int repeat = 1;
  bool no_ceres = false;
  po::options_description options =
      datasetOptions("arbor bench batch [options]", &data, default_shared);
  options.add_options()("repeat", po::value(&repeat)->default_value(1),
                        "runs per solver; the fastest is reported")(
      "no-ceres", po::bool_switch(&no_ceres), "skip the Ceres baseline");
  if (!parseOptions(args, options)) return 0;
  const auto files = bench::selectDatasets(data.shared, data.only);
  const auto refs = bench::readOptimumTable(data.shared);
  std::cout << "LM from a breadth-first spanning tree; Arbor vs Ceres "
               "(LEVENBERG_MARQUARDT, SPARSE_NORMAL_CHOLESKY, 100 it, ftol 1e-5, 1 thread). "
               "F = Σ eᵀΩe (the paper prints ½F). Fastest of "
            << repeat << " run(s).\n\n"
            << "| dataset | dim | poses | edges | F* | Arbor s | it | Arbor F | term | Ceres s "
               "| it | Ceres F | term | Arbor/Ceres |\n"
            << "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  bench::forEachDataset(files, [&](const bench::LoadedDataset& d) {
    const auto it = refs.find(d.name);
    const bench::Reference* ref = it == refs.end() ? nullptr : &it->second;
    std::visit([&](const auto& g) { benchBatch(d.name, g, ref, repeat, !no_ceres, d.note); },
               d.graph);
  });
  return 0;
}

// `arbor bench growth`: the replay's latency slice by slice as the graph grows, beside the cost
// of one batch factorisation of the graph so far (tools/bench/growth.h).
int growth(const std::vector<std::string>& args, const std::string& default_shared) {
  DatasetOptions data;
  std::string step;
  int slices = 8;
  cli::ReplaySettings settings;
  settings.finalize = false;
  settings.batch = false;
  po::options_description options =
      datasetOptions("arbor bench growth [options]", &data, default_shared);
  options.add_options()("slices", po::value(&slices)->default_value(8),
                        "slices of equal pose count per dataset")(
      "step", po::value(&step)->default_value("edge"), "edge or pose, as arbor replay --step");
  cli::addSmootherFlags(options);
  po::variables_map vm;
  if (!parseOptions(args, options, &vm)) return 0;
  if (slices < 1)
    throw cli::UsageError("--slices must be >= 1, not '" + std::to_string(slices) + "'");
  settings.smoother = cli::readSmootherFlags(vm);
  settings.per_pose = perPose(step);
  const bool per_pose = settings.per_pose;
  const auto files = bench::selectDatasets(data.shared, data.only);
  std::cout << "Replay (one update per " << step << ", " << cli::describeSmoother(settings.smoother)
            << ") in slices of equal pose count. \"relin.\": the updates "
               "that relinearised (every skip-th, when a variable's step exceeds β), their latency "
               "and the mean share of the poses they relinearised; \"factorisation\": flops of "
               "one sparse Cholesky factorisation of the graph so far (best of AMD, METIS, "
               "nested dissection) and its time on one thread with each backend; the faster is "
               "the least a step that relinearises the whole graph costs, and \"relin. / "
               "factorisation\" divides the median step by it.\n";
  bench::forEachDataset(files, [&](const bench::LoadedDataset& d) {
    std::visit(
        [&](const auto& g) {
          const auto replay = cli::runReplay(g, settings);
          std::cout << "\n### " << d.name << d.note << " (" << g.numPoses() << " poses, "
                    << g.numEdges() << " edges, " << fmt("%.3f", replay.update_s) << " s)\n\n";
          bench::printGrowthTable(std::cout, bench::growthSlices(g, replay, per_pose, slices));
          std::cout.flush();
        },
        d.graph);
  });
  return 0;
}

// Ceres as an external solver of the paper runner, with the same iteration cap and tolerance.
bench::ExternalSolver ceresSolver(const bench::PaperSettings& settings) {
  auto solve = [settings](const auto& graph, auto* poses) {
    const bench::CeresResult c =
        bench::solveWithCeres(graph, poses, settings.max_iterations, settings.relative_tolerance);
    bench::SolverRun run;
    run.time_s = c.time_s;
    run.iterations = c.iterations;
    run.termination = c.termination == "CONVERGENCE"      ? "converged"
                      : c.termination == "NO_CONVERGENCE" ? "max_iterations"
                                                          : "failed";
    if (run.termination == "failed") run.note = "Ceres: " + c.termination;
    return run;
  };
  return {"ceres", solve, solve};
}

std::string shellQuoted(const std::string& path) {
  std::string q = "'";
  for (char c : path) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

// Runs `command` with its standard output sent to standard error (ours carries the Markdown).
int runCommand(const std::string& command) {
  std::cerr << "arbor bench paper: " << command << std::endl;
  return std::system((command + " 1>&2").c_str());
}

int paper(const std::vector<std::string>& args, const std::string& default_shared) {
  DatasetOptions data;
  std::string out_dir, markdown, plot_dir;
  bool plots = false, no_ceres = false, no_replay = false;
  bench::PaperSettings settings;
  po::options_description options =
      datasetOptions("arbor bench paper [options]", &data, default_shared);
  options.add_options()("out-dir", po::value(&out_dir)->default_value("bench-paper"),
                        "write estimates/NAME/SOLVER.csv, latency/NAME.csv, results.tsv and "
                        "results.json here")("markdown", po::value(&markdown),
                                             "also write the Markdown tables to this file")(
      "plots", po::bool_switch(&plots),
      "draw the PNGs (tools/plots/plot_estimates.py, plot_latency.py; /usr/bin/python3 with "
      "matplotlib)")("plot-dir", po::value(&plot_dir),
                     "where the PNGs go (default: OUT_DIR/plots)")(
      "max-iterations", po::value(&settings.max_iterations)->default_value(100),
      "LM, GN, dogleg and Ceres iteration limit (the paper: 100)")(
      "rel-tol", po::value(&settings.relative_tolerance)->default_value(1e-5, "1e-5"),
      "LM, GN, dogleg and Ceres relative decrease of F to stop (the paper: 1e-5)")(
      "no-ceres", po::bool_switch(&no_ceres), "skip the Ceres baseline")(
      "no-replay", po::bool_switch(&no_replay), "skip the incremental replay");
  if (!parseOptions(args, options)) return 0;
  if (settings.max_iterations < 0) throw std::invalid_argument("--max-iterations must be >= 0");
  if (!(settings.relative_tolerance >= 0)) throw std::invalid_argument("--rel-tol must be >= 0");
  settings.out_dir = out_dir;
  settings.replay = !no_replay;
  std::filesystem::create_directories(out_dir);
  std::vector<bench::ExternalSolver> external;
  if (!no_ceres) external.push_back(ceresSolver(settings));

  const auto refs = bench::readOptimumTable(data.shared);
  std::vector<bench::DatasetReport> reports;
  bench::forEachDataset(data.shared, data.only, [&](const bench::LoadedDataset& d) {
    bench::DatasetReport report = std::visit(
        [&](const auto& g) { return bench::runPaperBenchmark(d.name, g, settings, external); },
        d.graph);
    report.note = d.note;
    const auto ref = refs.find(d.name);
    if (ref != refs.end()) report.F_star = ref->second.F_star;
    std::cerr << d.name << ":";
    for (const auto& r : report.runs) {
      std::cerr << " " << r.solver << " " << fmt("%.3f", r.time_s) << " s F " << fmt("%.7g", r.F)
                << " " << r.termination << ";";
    }
    std::cerr << std::endl;
    reports.push_back(std::move(report));
  });
  if (reports.empty())
    throw std::runtime_error("no shared dataset is named in --only " + data.only);
  bench::writeResultsTsv(out_dir + "/results.tsv", reports);
  bench::writeResultsJson(out_dir + "/results.json", reports);
  const std::string md = bench::paperMarkdown(reports);
  std::cout << md;
  if (!markdown.empty()) {
    std::ofstream out(markdown);
    out << md;
    if (!out) throw std::runtime_error("cannot write " + markdown);
  }
  if (plots) {
    if (plot_dir.empty()) plot_dir = out_dir + "/plots";
    std::filesystem::create_directories(plot_dir);
    const std::string plots_src = std::string(ARBOR_SOURCE_DIR) + "/tools/plots/";
    int rc = runCommand("/usr/bin/python3 " + shellQuoted(plots_src + "plot_estimates.py") + " " +
                        shellQuoted(out_dir) + " " + shellQuoted(plot_dir));
    std::string csvs;
    for (const auto& r : reports) {
      if (!r.latency_file.empty()) csvs += " " + shellQuoted(r.latency_file);
    }
    if (rc == 0 && !csvs.empty()) {
      rc = runCommand("/usr/bin/python3 " + shellQuoted(plots_src + "plot_latency.py") + " " +
                      shellQuoted(plot_dir) + csvs);
    }
    if (rc != 0)
      throw std::runtime_error("plotting failed (exit status " + std::to_string(rc) +
                               "); needs /usr/bin/python3 with matplotlib");
  }
  return 0;
}

/// Replaces this process by arbor-microbench (beside this executable) with `args`.
int micro(const std::vector<std::string>& args) {
  std::error_code ec;
  const auto self = std::filesystem::read_symlink("/proc/self/exe", ec);
  const std::string path =
      (ec ? std::filesystem::path(".") : self.parent_path()) / "arbor-microbench";
  std::vector<std::string> copy = args;
  std::string name = "arbor-microbench";
  std::vector<char*> argv = {name.data()};
  for (auto& a : copy) argv.push_back(a.data());
  argv.push_back(nullptr);
  execv(path.c_str(), argv.data());
  throw std::runtime_error("cannot run " + path + ": " + std::strerror(errno));
}

}  // namespace

int main(int argc, char** argv) {
  arbor::useOneBlasThread();  // first thing: stops OpenBLAS's idle workers early
  const std::vector<std::string> args(argv + 1, argv + argc);
  if (args.empty() || args[0] == "--help" || args[0] == "help") {
    std::cout
        << "usage: arbor bench batch [--shared DIR] [--only NAMES] [--repeat N] [--no-ceres]\n"
           "       arbor bench replay [--shared DIR] [--only NAMES] [--csv-dir DIR] [--step "
           "edge|pose] [smoother flags]\n"
           "       arbor bench paper [--shared DIR] [--only NAMES] [--out-dir DIR] "
           "[--markdown FILE] [--plots]\n"
           "       arbor bench growth [--shared DIR] [--only NAMES] [--slices K] [--step "
           "edge|pose] [smoother flags]\n"
           "  smoother flags: as arbor replay (--relinearize-threshold B, --relinearize-skip K, "
           "--dogleg, ...; arbor bench replay --help lists them)\n"
           "       arbor bench micro [--sizes=N,...] [--benchmark_filter=REGEX ...]\n";
    return args.empty() ? 2 : 0;
  }
  try {
    const std::vector<std::string> rest(args.begin() + 1, args.end());
    if (args[0] == "batch") return batch(rest, ARBOR_SHARED_DIR);
    if (args[0] == "replay") return replay(rest, ARBOR_SHARED_DIR);
    if (args[0] == "paper") return paper(rest, ARBOR_SHARED_DIR);
    if (args[0] == "growth") return growth(rest, ARBOR_SHARED_DIR);
    if (args[0] == "micro") return micro(rest);
    std::cerr << "arbor bench: unknown benchmark '" << args[0] << "'\n";
    return 2;
  } catch (const arbor::cli::UsageError& e) {
    std::cerr << "arbor bench " << args[0] << ": " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "arbor bench: " << e.what() << "\n";
    return 1;
  }
}
