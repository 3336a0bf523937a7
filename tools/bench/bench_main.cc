// arbor-bench: benchmarks on the shared datasets (run as `arbor bench ...`).
//   arbor-bench batch [--shared DIR] [--only NAME,...] [--repeat N] [--no-ceres]
//     LM from a spanning-tree start for Arbor and for Ceres (the paper's settings), a Markdown
//     table like the paper's Table II on stdout.
//   arbor-bench replay [--shared DIR] [--only NAME,...] [--csv-dir DIR]
//     edge-by-edge replay through the incremental smoother beside GTSAM iSAM2's figures.
//   arbor-bench micro [--sizes=N,...] [--benchmark_* flags]
//     the Google Benchmark microbenchmarks: runs `arbor-microbench` built beside this program.
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <set>
#include <sstream>

#include <boost/program_options.hpp>

#include "core/batch_solver.h"
#include "core/initialization.h"
#include "io/pose_graph_file.h"
#include "tools/bench/ceres_pose_graph.h"
#include "tools/bench/shared_data.h"
#include "tools/cli/replay_runner.h"

namespace {

namespace po = boost::program_options;
using namespace arbor;

std::string fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

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
    BatchOptions options;
    options.method = BatchMethod::kLevenbergMarquardt;
    const BatchSummary s = solveBatch(graph, &poses, options);
    if (s.time_s < ours.time) ours = {s.time_s, s.iterations, s.F_final, toString(s.termination)};
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

// Reads a shared dataset; a file refused for indefinite information (cubicle) is read again
// with Ω repaired, and `note` says so.
AnyPoseGraph loadDataset(const std::string& file, std::string* note) {
  ReadReport report;
  try {
    return readPoseGraphFile(file, ReadOptions{}, &report);
  } catch (const FileError&) {
    ReadOptions read;
    read.information = InformationPolicy::kRepair;
    AnyPoseGraph any = readPoseGraphFile(file, read, &report);
    *note = " (Ω repaired: " + std::to_string(report.repaired) + ")";
    return any;
  }
}

std::set<std::string> splitNames(const std::string& only) {
  std::set<std::string> wanted;
  std::stringstream list(only);
  for (std::string item; std::getline(list, item, ',');) wanted.insert(item);
  return wanted;
}

template <class G>
void benchReplay(const std::string& name, const PoseGraph<G>& graph, const bench::Reference* ref,
                 const bench::Anchor* gtsam, const std::string& csv_dir, const std::string& note) {
  cli::ReplaySettings settings;
  const cli::ReplayResult<G> r = cli::runReplay(graph, settings);
  if (!csv_dir.empty()) cli::writeLatencyCsv(csv_dir + "/" + name + ".csv", r.rows);
  const auto& l = r.latency;
  std::cout << "| " << name << note << " | " << graph.numEdges() << " | " << fmt("%.3f", r.total_s)
            << " | " << fmt("%.3f", l.p50) << " | " << fmt("%.3f", l.p99) << " | "
            << fmt("%.2f", l.max) << " | " << fmt("%.6e", r.F_final) << " | "
            << (ref ? fmt("%+.3f%%", 100.0 * (r.F_final - ref->F_star) / ref->F_star) : "—")
            << " | " << fmt("%.3f", r.batch.time_s) << " | " << fmt("%.6e", r.batch.F_final)
            << " | ";
  if (gtsam) {
    std::cout << fmt("%.3f", gtsam->total_s) << " | " << fmt("%.2f", gtsam->p99_ms) << " | "
              << fmt("%.6e", gtsam->F) << " | " << fmt("%.2f", r.total_s / gtsam->total_s) << " | "
              << fmt("%.2f", l.p99 / gtsam->p99_ms) << " |";
  } else {
    std::cout << "aborted | — | — | — | — |";
  }
  if (r.indeterminate) std::cout << " " << r.indeterminate << " cliques damped";
  std::cout << std::endl;
}

int replay(const std::vector<std::string>& args, const std::string& default_shared) {
  std::string shared, only, csv_dir;
  po::options_description options("arbor bench replay [options]");
  options.add_options()("help,h", "show this help")(
      "shared", po::value(&shared)->default_value(bench::sharedDirectory(default_shared)),
      "the shared folder (datasets/, reference/)")("only", po::value(&only),
                                                   "comma-separated dataset names")(
      "csv-dir", po::value(&csv_dir), "write per-update latency CSVs (NAME.csv) here");
  po::variables_map vm;
  po::store(po::command_line_parser(args).options(options).run(), vm);
  po::notify(vm);
  if (vm.count("help")) {
    std::cout << options << "\n";
    return 0;
  }
  const auto wanted = splitNames(only);
  const auto files = bench::sharedDatasets(shared);
  if (files.empty()) {
    std::cerr << "arbor bench: no shared datasets at " << shared << "/datasets\n";
    return 1;
  }
  const auto refs = bench::readOptimumTable(shared);
  const auto anchors = bench::readAnchorTable(shared);
  std::cout << "Edge-by-edge replay (GN, β = 0.1, skip 10, wildfire 0.001, final relinearise-all "
               "pass), then batch LM from its estimate. GTSAM: iSAM2 per edge from "
               "reference/anchors.tsv (update() only; its back-substitution is deferred).\n\n"
            << "| dataset | edges | total s | p50 ms | p99 ms | max ms | F_final | vs F* | LM s | "
               "LM F | GTSAM s | GTSAM p99 | GTSAM F | total/GTSAM | p99/GTSAM |\n"
            << "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const auto& file : files) {
    const std::string name = bench::datasetName(file);
    if (!wanted.empty() && !wanted.count(name)) continue;
    std::string note;
    AnyPoseGraph any = loadDataset(file, &note);
    const auto ref = refs.find(name);
    const auto gtsam = anchors.find({name, "isam2_edge"});
    std::visit(
        [&](const auto& g) {
          benchReplay(name, g, ref == refs.end() ? nullptr : &ref->second,
                      gtsam == anchors.end() ? nullptr : &gtsam->second, csv_dir, note);
        },
        any);
  }
  return 0;
}

int batch(const std::vector<std::string>& args, const std::string& default_shared) {
  std::string shared, only;
  int repeat = 1;
  bool no_ceres = false;
  po::options_description options("arbor bench batch [options]");
  options.add_options()("help,h", "show this help")(
      "shared", po::value(&shared)->default_value(bench::sharedDirectory(default_shared)),
      "the shared folder (datasets/, reference/)")("only", po::value(&only),
                                                   "comma-separated dataset names")(
      "repeat", po::value(&repeat)->default_value(1), "runs per solver; the fastest is reported")(
      "no-ceres", po::bool_switch(&no_ceres), "skip the Ceres baseline");
  po::variables_map vm;
  po::store(po::command_line_parser(args).options(options).run(), vm);
  po::notify(vm);
  if (vm.count("help")) {
    std::cout << options << "\n";
    return 0;
  }
  const auto wanted = splitNames(only);

  const auto files = bench::sharedDatasets(shared);
  if (files.empty()) {
    std::cerr << "arbor bench: no shared datasets at " << shared << "/datasets\n";
    return 1;
  }
  const auto refs = bench::readOptimumTable(shared);
  std::cout << "LM from a breadth-first spanning tree; Arbor vs Ceres "
               "(LEVENBERG_MARQUARDT, SPARSE_NORMAL_CHOLESKY, 100 it, ftol 1e-5, 1 thread). "
               "F = Σ eᵀΩe (the paper prints ½F). Fastest of "
            << repeat << " run(s).\n\n"
            << "| dataset | dim | poses | edges | F* | Arbor s | it | Arbor F | term | Ceres s "
               "| it | Ceres F | term | Arbor/Ceres |\n"
            << "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const auto& file : files) {
    const std::string name = bench::datasetName(file);
    if (!wanted.empty() && !wanted.count(name)) continue;
    std::string note;
    AnyPoseGraph any = loadDataset(file, &note);
    const auto it = refs.find(name);
    const bench::Reference* ref = it == refs.end() ? nullptr : &it->second;
    std::visit([&](const auto& g) { benchBatch(name, g, ref, repeat, !no_ceres, note); }, any);
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
  const std::vector<std::string> args(argv + 1, argv + argc);
  if (args.empty() || args[0] == "--help" || args[0] == "help") {
    std::cout
        << "usage: arbor bench batch [--shared DIR] [--only NAMES] [--repeat N] [--no-ceres]\n"
           "       arbor bench replay [--shared DIR] [--only NAMES] [--csv-dir DIR]\n"
           "       arbor bench micro [--sizes=N,...] [--benchmark_filter=REGEX ...]\n";
    return args.empty() ? 2 : 0;
  }
  try {
    const std::vector<std::string> rest(args.begin() + 1, args.end());
    if (args[0] == "batch") return batch(rest, ARBOR_SHARED_DIR);
    if (args[0] == "replay") return replay(rest, ARBOR_SHARED_DIR);
    if (args[0] == "micro") return micro(rest);
    std::cerr << "arbor bench: unknown benchmark '" << args[0] << "'\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "arbor bench: " << e.what() << "\n";
    return 1;
  }
}
