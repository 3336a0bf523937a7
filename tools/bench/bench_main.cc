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
//   arbor-bench covariance [--shared DIR] [--only NAME,...] [--samples K] [--no-ceres]
//     marginal covariances at the end of a replay: one pose's cost beside an update's p50, and
//     (2D) the agreement with ceres::Covariance.
//   arbor-bench robust [--shared DIR] [--only NAME,...] [--no-generated] [--generate-from NAMES]
//                      [--fractions F,...] [--policies P,...] [--seed S] [--kernel K]
//                      [--inlier-threshold X] [--solver lm|rtr] [--repeat N]
//                      [--keep-generated DIR]
//     the robust batch (GNC over LM, as `arbor batch --robust`) on the shared files with false
//     loop closures and on its own, generated from shared clean sets (tools/bench/robust_bench.h).
//   arbor-bench robust --family NAMES [--seeds A-B] [--dims 2,3] [--fractions F,...]
//                      [--policies P,...] [...]
//     issue 52's held-out protocol: the generated families' worlds instead
//     (tools/bench/family_bench.h).
//   arbor-bench tree [--shared DIR] [--only NAME,...] [--ratios R,...]
//     the Bayes tree's cliques, flops and memory on each whole graph in a fresh ordering,
//     symbolic only, for cached-factor ratios, and what the last tenth's loop closures cost in
//     it (tools/bench/tree_size.h).
//   arbor-bench micro [--sizes=N,...] [--benchmark_* flags]
//     the Google Benchmark microbenchmarks: runs `arbor-microbench` built beside this program.
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <optional>
#include <sstream>
#include <type_traits>

#include <boost/program_options.hpp>

#include "arbor_slam/core/blas_threads.h"
#include "arbor_slam/core/initialization.h"
#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/tools/bench/ablation.h"
#include "arbor_slam/tools/bench/ceres_pose_graph.h"
#include "arbor_slam/tools/bench/family_bench.h"
#include "arbor_slam/tools/bench/format.h"
#include "arbor_slam/tools/bench/growth.h"
#include "arbor_slam/tools/bench/paper_runner.h"
#include "arbor_slam/tools/bench/robust_bench.h"
#include "arbor_slam/tools/bench/robust_replay_hooks.h"
#include "arbor_slam/tools/bench/shared_data.h"
#include "arbor_slam/tools/bench/tree_size.h"
#include "arbor_slam/tools/bench/world_families.h"
#include "arbor_slam/tools/cli/cli_common.h"
#include "arbor_slam/tools/cli/flag_set.h"
#include "arbor_slam/tools/cli/replay_runner.h"
#include "arbor_slam/tools/cli/robust_flags.h"
#include "arbor_slam/tools/cli/smoother_flags.h"
#include "arbor_slam/tools/refine/batch_solvers.h"

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

// The options every dataset benchmark takes (--shared, --only), listed first under "Datasets";
// the caller adds its own after them (under kBench, and the smoother table's).
struct DatasetOptions {
  std::string shared, only;
};

const char* const kBench = "Benchmark";

// `usage` and two `examples` for --help (tools/cli/flag_set.h).
cli::FlagSet datasetFlags(const std::string& usage, std::vector<std::string> examples,
                          DatasetOptions* data, const std::string& default_shared) {
  cli::FlagSet flags(usage, std::move(examples));
  flags.add(cli::Tier::kCommon, "Datasets")(
      "shared",
      po::value(&data->shared)
          ->default_value(bench::sharedDirectory(default_shared))
          ->value_name("DIR"),
      "the shared folder (datasets/, reference/)")(
      "only", po::value(&data->only)->value_name("NAMES"), "comma-separated dataset names");
  return flags;
}

// One item of a comma-separated list of numbers: the whole item a finite number >= 0, else
// cli::UsageError "FLAG: 'ITEM' is not a WHAT >= 0" (an empty item included).
double finiteNonNegative(const std::string& item, const std::string& flag,
                         const std::string& what) {
  char* end = nullptr;
  const double value = std::strtod(item.c_str(), &end);
  if (end == item.c_str() || *end != '\0' || !(value >= 0) || !std::isfinite(value))
    throw cli::UsageError(flag + ": '" + item + "' is not a " + what + " >= 0");
  return value;
}

// Parses `args` into the variables bound to `flags` (and into *vm when given); false (after
// printing the help) on --help or --help-all. Throws cli::UsageError (exit 2) on a bad command
// line, a prefix of a flag included.
bool parseOptions(const std::vector<std::string>& args, const cli::FlagSet& flags,
                  po::variables_map* vm = nullptr) {
  std::optional<po::variables_map> parsed = flags.parse(args);
  if (!parsed) return false;
  if (vm) *vm = std::move(*parsed);
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
  cli::FlagSet options = datasetFlags("arbor bench replay [options]",
                                      {"arbor bench replay --only M3500,sphere2500",
                                       "arbor bench replay --step pose --csv-dir latency/"},
                                      &data, default_shared);
  options.add(cli::Tier::kCommon, kBench)("csv-dir", po::value(&csv_dir),
                                          "write per-update latency CSVs (NAME.csv) here")(
      "step", po::value(&step)->default_value("edge"),
      "edge: an update per edge (against GTSAM's isam2_edge rows); pose: per new pose with its "
      "edges (against isam2_pose)");
  options.add(cli::smootherOptionTable());
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
  cli::FlagSet options =
      datasetFlags("arbor bench batch [options]",
                   {"arbor bench batch --only M3500", "arbor bench batch --repeat 3 --no-ceres"},
                   &data, default_shared);
  options.add(cli::Tier::kCommon, kBench)("repeat", po::value(&repeat)->default_value(1),
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

// `arbor bench covariance`: at the end of a replay (after its final pass), the cost of one
// pose's marginal covariance from the Bayes tree beside one update's p50 (issue 15's goal:
// ≤ 10×), and in 2D its agreement with ceres::Covariance at the same linearisation point.
template <class G>
void benchCovariance(const std::string& name, const PoseGraph<G>& graph,
                     const cli::ReplaySettings& settings, int samples, bool ceres) {
  // CPU time of the process (every thread), not wall time: the machine is shared, and a
  // descheduled query is not a slower one.
  auto cpuMs = [] {
    timespec t{};
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return static_cast<double>(t.tv_sec) * 1e3 + static_cast<double>(t.tv_nsec) * 1e-6;
  };
  auto now = cpuMs;
  auto ms = [&](double t0) { return now() - t0; };
  OnlineSmootherOptions<G> options;
  options.smoother = settings.smoother;
  OnlineSmoother<G> online(options);
  // One replay step's CPU time: from one update's end to the next's (the edge's insertion and
  // its update).
  // Live: after each of the last `samples` updates, one pose's marginal on the smoother itself
  // (poses spread over those present), as a front-end gating a loop closure asks for it: the
  // tree as that update left it in the cache, not a copy's.
  std::vector<double> steps, live;
  double last = now();
  const int updates_expected = static_cast<int>(graph.edges.size());
  int updates_seen = 0;
  double checksum = 0;
  cli::ReplayHooks<G> hooks;
  hooks.after_update = [&](OnlineSmoother<G>& o, cli::UpdateRow&) {
    const double t = now();
    steps.push_back(t - last);
    const int k = updates_expected - ++updates_seen;  // updates still to come
    const int np = o.smoother().numPoses();
    if (k >= 0 && k < samples && np > 1) {
      const int v = static_cast<int>((static_cast<long>(k) * (np - 1)) / std::max(1, samples - 1));
      if (!o.smoother().isFixed(v)) {
        const double q0 = now();
        checksum += o.smoother().marginalCovariance(v).trace();
        live.push_back(ms(q0));
      }
    }
    last = now();
  };
  const cli::ReplayResult<G> r = cli::replayInto(graph, settings, online, hooks);
  const double update_p50 = summarizeLatency(steps).p50;
  const IncrementalSmoother<G>& s = online.smoother();
  const int n = s.numPoses();
  // Cold: each sample on a copy of the smoother (a copy starts with empty scratch), poses
  // spread over the dense order; warm: the neighbouring pose next, on the same copy.
  std::vector<double> cold, warm, joint;
  for (int k = 0; k < samples; ++k) {
    const int v = static_cast<int>((static_cast<long>(k) * (n - 1)) / std::max(1, samples - 1));
    if (s.isFixed(v)) continue;
    IncrementalSmoother<G> copy = s;
    auto t0 = now();
    checksum += copy.marginalCovariance(v).trace();
    cold.push_back(ms(t0));
    const int w = v > 0 ? v - 1 : v + 1;
    t0 = now();
    checksum += copy.marginalCovariance(w).trace();
    warm.push_back(ms(t0));
    IncrementalSmoother<G> other = s;
    t0 = now();
    checksum += other.jointMarginalCovariance(v, (v + n / 2) % n).trace();
    joint.push_back(ms(t0));
  }
  auto t0 = now();
  const auto all = s.marginalCovariances();
  const double all_ms = ms(t0);
  const auto c = summarizeLatency(cold), wm = summarizeLatency(warm), j = summarizeLatency(joint),
             lv = summarizeLatency(live);
  const TreeMemory mem = s.memory();
  std::cout << "| " << name << " | " << n << " | " << fmt("%.4f", update_p50) << " | "
            << fmt("%.4f", c.p50) << " | " << fmt("%.3f", c.max) << " | "
            << fmt("%.2f", c.p50 / update_p50) << " | " << fmt("%.4f", lv.p50) << " | "
            << fmt("%.3f", lv.max) << " | " << fmt("%.2f", lv.p50 / update_p50) << " | "
            << fmt("%.4f", wm.p50) << " | " << fmt("%.3f", j.p50) << " | " << fmt("%.1f", all_ms)
            << " | " << mem.max_frontal_dim << " | ";
  if constexpr (std::is_same_v<G, SE2>) {
    if (ceres) {
      // θ and the fixed poses in the graph's dense order.
      std::vector<SE2> theta(graph.numPoses());
      std::vector<int> fixed;
      std::vector<int> at(n);
      for (int v = 0; v < n; ++v) {
        at[v] = graph.index.at(online.ids()[v]);
        theta[at[v]] = s.linearizationPoint()[v];
        if (s.isFixed(v)) fixed.push_back(at[v]);
      }
      double ceres_s = 0;
      const auto theirs = bench::ceresCovariances(graph, theta, fixed, &ceres_s);
      std::vector<double> rel;
      for (int v = 0; v < n; ++v)
        if (!s.isFixed(v)) rel.push_back((all[v] - theirs[at[v]]).norm() / theirs[at[v]].norm());
      std::sort(rel.begin(), rel.end());
      std::cout << fmt("%.1e", rel[rel.size() / 2]) << " | " << fmt("%.1e", rel.back()) << " | "
                << fmt("%.2f", ceres_s) << " |";
    } else {
      std::cout << "— | — | — |";
    }
  } else {
    std::cout << "— | — | — |";
  }
  std::cout << (checksum > 0 ? "" : " (non-positive trace!)") << std::endl;
}

int covariance(const std::vector<std::string>& args, const std::string& default_shared) {
  DatasetOptions data;
  int samples = 20;
  bool no_ceres = false;
  cli::FlagSet options = datasetFlags(
      "arbor bench covariance [options]",
      {"arbor bench covariance --only M3500 --samples 10", "arbor bench covariance --no-ceres"},
      &data, default_shared);
  options.add(cli::Tier::kCommon, kBench)(
      "samples", po::value(&samples)->default_value(20),
      "poses timed (spread over the graph), each on a fresh copy of the smoother")(
      "no-ceres", po::bool_switch(&no_ceres), "skip the comparison with ceres::Covariance");
  options.add(cli::smootherOptionTable());
  po::variables_map vm;
  if (!parseOptions(args, options, &vm)) return 0;
  if (samples < 1) throw cli::UsageError("--samples must be >= 1");
  cli::ReplaySettings settings;
  settings.smoother = cli::readSmootherFlags(vm);
  settings.batch = false;
  const auto files =
      bench::selectDatasets(data.shared, data.only.empty() ? "M3500,intel" : data.only);
  std::cout
      << "Edge-by-edge replay (" << cli::describeSmoother(settings.smoother)
      << ", final relinearise-all pass), then marginal covariances from its Bayes tree. "
         "Times are CPU ms of the process (CLOCK_PROCESS_CPUTIME_ID); update: one replay "
         "step (insertion and update). cold: one pose on a fresh copy of the smoother ("
      << samples
      << " poses spread over the graph); live: one pose on the smoother itself after each of "
         "the last "
      << samples
      << " updates (spread likewise); warm: the cold one's neighbour next; joint: two poses half "
         "the graph apart, cold; all: every pose in one walk. Ceres: ceres::Covariance "
         "(SPARSE_QR) at the same linearisation point, relative Frobenius difference per "
         "pose.\n\n"
      << "| dataset | poses | update p50 CPU ms | marginal cold p50 CPU ms | cold max ms | "
         "cold p50 / update p50 | live p50 ms | live max ms | live p50 / update p50 | warm "
         "p50 ms | joint cold p50 ms | all ms | max frontal dim | vs Ceres median | vs Ceres "
         "max | Ceres s |\n"
      << "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  bench::forEachDataset(files, [&](const bench::LoadedDataset& d) {
    std::visit([&](const auto& g) { benchCovariance(d.name, g, settings, samples, !no_ceres); },
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
  cli::FlagSet options = datasetFlags(
      "arbor bench growth [options]",
      {"arbor bench growth --only M3500 --slices 4", "arbor bench growth --step pose --threads 2"},
      &data, default_shared);
  options.add(cli::Tier::kCommon, kBench)("slices", po::value(&slices)->default_value(8),
                                          "slices of equal pose count per dataset")(
      "step", po::value(&step)->default_value("edge"), "edge or pose, as arbor replay --step");
  options.add(cli::smootherOptionTable());
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
               "nested dissection) and its time on one thread with each backend, and \"relin. / "
               "factorisation\" divides the median step by the faster; \"linearisation\": the "
               "time of linearising every factor with that backend, which a step that "
               "relinearises the whole graph pays besides.\n";
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

// `arbor bench tree`: what the smoother's Bayes tree holds on each whole graph in a fresh
// ordering, with every cached factor and at each ratio (tools/bench/tree_size.h).
int tree(const std::vector<std::string>& args, const std::string& default_shared) {
  DatasetOptions data;
  std::string ratios_text;
  cli::FlagSet options = datasetFlags(
      "arbor bench tree [options]",
      {"arbor bench tree --only M3500", "arbor bench tree --ratios 0,4"}, &data, default_shared);
  options.add(cli::Tier::kCommon, kBench)(
      "ratios", po::value(&ratios_text)->default_value("0,16,4,1"),
      "comma-separated CachedFactorOptions::max_ratio values (0: every clique "
      "keeps its cached factor)");
  if (!parseOptions(args, options)) return 0;
  std::vector<double> ratios;
  std::stringstream list(ratios_text);
  for (std::string item; std::getline(list, item, ',');)
    ratios.push_back(finiteNonNegative(item, "--ratios", "finite number"));
  std::cout << "The smoother's Bayes tree on each whole graph in a fresh, unconstrained ordering "
               "(what a batch re-elimination makes; symbolic only). Per clique of F frontal and S "
               "separator dimensions: the conditional F(F+S) + F doubles, the cached factor S^2 "
               "+ S unless the ratio drops it (S^2 > ratio * F(F+S)).\n";
  bench::forEachDataset(data.shared, data.only, [&](const bench::LoadedDataset& d) {
    std::visit(
        [&](const auto& g) {
          std::cout << "\n### " << d.name << d.note << " (" << g.numPoses() << " poses, "
                    << g.numEdges() << " edges)\n\n";
          const bench::TreeReport report = bench::treeReport(g, ratios);
          bench::printTreeSizeTable(std::cout, report.sizes, g.numPoses());
          std::cout << "\nThe last tenth of the edges (file order) in that tree: the cliques a "
                       "loop closure reaches and what re-eliminating them or a rank update "
                       "through them costs (odometry counted free; a floor on those updates, "
                       "not a measurement).\n\n";
          bench::printPathCostTable(std::cout, report.paths);
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
  cli::FlagSet options =
      datasetFlags("arbor bench paper [options]",
                   {"arbor bench paper --out-dir bench-paper --markdown paper.md",
                    "arbor bench paper --only M3500 --no-ceres --plots"},
                   &data, default_shared);
  options.add(cli::Tier::kCommon, kBench)(
      "out-dir", po::value(&out_dir)->default_value("bench-paper"),
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

// The first three fields of /proc/loadavg ("1.20 1.66 1.85"), "unknown" if unreadable.
std::string loadAverage() {
  std::ifstream in("/proc/loadavg");
  std::string a, b, c;
  if (!(in >> a >> b >> c)) return "unknown";
  return a + " " + b + " " + c;
}

// A comma-separated list, empty items dropped.
std::vector<std::string> splitList(const std::string& list) {
  std::vector<std::string> items;
  std::stringstream in(list);
  for (std::string item; std::getline(in, item, ',');) {
    if (!item.empty()) items.push_back(item);
  }
  return items;
}

// Removes the temporary directory of the generated files when the benchmark ends.
struct TemporaryDirectory {
  std::string path;
  ~TemporaryDirectory() {
    std::error_code ec;
    if (!path.empty()) std::filesystem::remove_all(path, ec);
  }
};

// The directory the generated files go to: `keep_dir` (made if absent), else a fresh temporary
// one that `temporary` removes at the end.
std::string generatedDirectory(const std::string& keep_dir, TemporaryDirectory* temporary) {
  if (!keep_dir.empty()) {
    std::filesystem::create_directories(keep_dir);
    return keep_dir;
  }
  std::string pattern =
      (std::filesystem::temp_directory_path() / "arbor-bench-robust-XXXXXX").string();
  if (!mkdtemp(pattern.data()))
    throw std::runtime_error("cannot make a temporary directory " + pattern + ": " +
                             std::strerror(errno));
  return temporary->path = pattern;
}

// `arbor bench robust --family NAMES`: issue 52's held-out protocol (tools/bench/family_bench.h).
int robustFamilies(const DatasetOptions& data, const std::string& families, std::string seeds,
                   std::string dims, const std::string& fractions, const std::string& policies,
                   const bench::GenerationPlan& lists, const bench::RobustBatchSettings& settings,
                   int repeat, const std::string& keep_dir, const std::string& ablate) {
  if (seeds.empty()) seeds = "1-3";
  const bench::Ablation* rule_off = nullptr;
  RobustOptions online;
  if (!ablate.empty()) {
    try {
      rule_off = &bench::ablation(ablate);
    } catch (const std::invalid_argument& e) {
      throw cli::UsageError(e.what());
    }
    rule_off->off(&online);
  }
  if (dims.empty()) dims = "2,3";
  bench::FamilyPlan plan;
  plan.families = splitList(families);
  try {
    plan.seeds = bench::parseSeedRange(seeds);
  } catch (const std::invalid_argument& e) {
    throw cli::UsageError(e.what());
  }
  plan.dims.clear();
  for (const std::string& d : splitList(dims)) {
    if (d != "2" && d != "3") throw cli::UsageError("--dims: '" + d + "' is not 2 or 3");
    plan.dims.push_back(d == "2" ? 2 : 3);
  }
  plan.fractions = lists.fractions;
  plan.policies = lists.policies;
  for (const std::string& f : plan.families) {
    if (!bench::worldFamily(f)) {
      std::string known;
      for (const std::string& n : bench::worldFamilyNames())
        known += (known.empty() ? "" : ", ") + n;
      throw cli::UsageError("--family: unknown family '" + f + "' (" + known + ")");
    }
  }
  if (plan.families.empty() || plan.dims.empty() || plan.fractions.empty() || plan.policies.empty())
    throw cli::UsageError("--family, --dims, --fractions and --policies must name at least one");
  TemporaryDirectory temporary;
  const std::string out_dir = generatedDirectory(keep_dir, &temporary);
  std::vector<bench::RobustCase> cases = bench::generateFamilyCases(plan, out_dir);
  cases = bench::selectCases(cases, data.only);
  if (cases.empty()) throw std::runtime_error("no family case is named in --only " + data.only);
  const std::string load_before = loadAverage();
  const bench::RobustReplayHooks hooks =
      bench::robustReplayHooks(settings.gnc.kernel, repeat, online);
  const auto rows = bench::runRobustBench(cases, {}, {}, settings, hooks, &std::cerr);
  if (rule_off)
    std::cout << "Ablation: rule " << rule_off->name << " off (RobustOptions::" << rule_off->field
              << "; it guarantees: " << rule_off->property
              << ") in the replay rows; the batch rows run the defaults.\n";
  std::cout << "Held-out protocol (issue 52): families " << families << ", dims " << dims
            << ", seeds " << seeds << ", fractions " << fractions << ", policies " << policies
            << ". Each world generated in memory and written to "
            << (keep_dir.empty() ? "a temporary directory" : keep_dir)
            << "; its false closures planted with its seed; F* its clean optimum (LM from the "
               "odometry chain, or the certifiable solver where lower). Replay: `arbor replay "
               "--robust` with the defaults; batch: `arbor batch --robust` with the defaults"
            << (settings.start == bench::BatchStart::kOnline ? "" : " but --init file")
            << ". Solved: F over the world's edges within 1% of F*, precision and recall of "
               "the rejected edges >= 0.95. X: Ω written = X · the drawn noise's information. "
               "Load average "
            << load_before << " at the start, " << loadAverage() << " at the end.\n\n";
  std::cout << bench::familyMarkdown(rows);
  return 0;
}

// --generate-from's default: a 2D and a 3D shared clean set.
const char* const kGenerateFrom = "intel,smallGrid3D";

// `arbor bench robust`: tools/bench/robust_bench.h.
int robust(const std::vector<std::string>& args, const std::string& default_shared) {
  DatasetOptions data;
  bool no_generated = false;
  std::string generate_from, fractions, policies, kernel = "tls", threshold = "chi2", solver,
                                                  keep_dir, batch_start, families, seeds, dims,
                                                  ablate;
  int repeat = 3;
  bench::GenerationPlan plan;
  cli::FlagSet options =
      datasetFlags("arbor bench robust [options]",
                   {"arbor bench robust --only M3500 --fractions 0.1 --policies random",
                    "arbor bench robust --family vehicle --seeds 1-3 --dims 2"},
                   &data, default_shared);
  options.add(cli::Tier::kCommon, kBench)("no-generated", po::bool_switch(&no_generated),
                                          "only the shared files of DIR/datasets/robust")(
      "generate-from", po::value(&generate_from)->default_value(kGenerateFrom),
      "shared clean sets (names in DIR/datasets) to plant false closures in")(
      "fractions", po::value(&fractions)->default_value("0.1,0.5,0.9"),
      "false closures per loop closure of the base, one generated file each")(
      "policies", po::value(&policies)->default_value("random,local,group"),
      "random | local | group, one generated file each")(
      "seed", po::value(&plan.seed)->default_value(plan.seed), "the generator's seed")(
      "kernel", po::value(&kernel)->default_value(kernel), cli::kKernelHelp)(
      "inlier-threshold", po::value(&threshold)->default_value(threshold),
      cli::kInlierThresholdHelp)("solver", po::value(&solver)->default_value("lm"),
                                 "lm: GNC over LM; rtr: then the certifiable solver on GNC's "
                                 "inlier set (as arbor batch --robust --solver rtr)");
  options.add(cli::Tier::kAdvanced, kBench)(
      "batch-start", po::value(&batch_start)->default_value("online"),
      "online: the robust batch from the robust online replay, its rejected closures held out "
      "and its threshold (arbor batch --robust's defaults); file: from the file's vertices at "
      "--inlier-threshold (arbor batch --robust --init file, GTSAM's GncOptimizer)")(
      "repeat", po::value(&repeat)->default_value(repeat),
      "run each replay (robust and clean) this many times and report the fastest run's time "
      "and latency (the runs are deterministic: the same estimate and classification)")(
      "keep-generated", po::value(&keep_dir),
      "write the generated files (NAME.g2o, NAME.labels) here and keep them (default: a "
      "temporary directory, removed at the end)")(
      "family", po::value(&families),
      "issue 52's held-out protocol instead of the shared and generate-from files: the "
      "generated worlds of these families (vehicle, small-loop, over-confident), each × "
      "--dims × --seeds × --fractions × --policies, F* each world's clean optimum")(
      "seeds", po::value(&seeds),
      "with --family: the worlds' seeds, A-B or A (default 1-3, the tuning seeds; 4-10 are held "
      "out)")("dims", po::value(&dims), "with --family: 2, 3 or 2,3 (default 2,3)")(
      "ablate", po::value(&ablate),
      "with --family: the replay with this rule of the robust layer off (end-word, "
      "final-confirm, end-scale, rehold, corroboration, "
      "scale-start, warm-up, estimated-scale; tools/bench/ablation.h)");
  if (!parseOptions(args, options)) return 0;
  if (families.empty() && !seeds.empty()) throw cli::UsageError("--seeds needs --family NAMES");
  if (families.empty() && !dims.empty()) throw cli::UsageError("--dims needs --family NAMES");
  if (families.empty() && !ablate.empty()) throw cli::UsageError("--ablate needs --family NAMES");
  bench::RobustBatchSettings settings;
  cli::readRobustFlags(kernel, threshold, &settings.gnc);
  if (solver != "lm" && solver != "rtr")
    throw cli::UsageError("--solver must be lm or rtr, not '" + solver + "'");
  settings.certify = solver == "rtr";
  if (repeat < 1) throw cli::UsageError("--repeat must be >= 1, not " + std::to_string(repeat));
  if (batch_start != "file" && batch_start != "online")
    throw cli::UsageError("--batch-start must be file or online, not '" + batch_start + "'");
  settings.start = batch_start == "online" ? bench::BatchStart::kOnline : bench::BatchStart::kFile;
  plan.bases = splitList(generate_from);
  plan.fractions.clear();
  for (const std::string& f : splitList(fractions))
    plan.fractions.push_back(finiteNonNegative(f, "--fractions", "finite fraction"));
  plan.policies.clear();
  for (const std::string& p : splitList(policies)) {
    const auto policy = sim::parseOutlierPolicy(p);
    if (!policy) throw cli::UsageError("--policies: '" + p + "' is not random, local or group");
    plan.policies.push_back(*policy);
  }

  if (!families.empty() && (no_generated || generate_from != kGenerateFrom || plan.seed != 1))
    throw cli::UsageError(
        "--no-generated, --generate-from and --seed do not apply with --family (its worlds' "
        "seeds are --seeds)");
  if (!families.empty())
    return robustFamilies(data, families, seeds, dims, fractions, policies, plan, settings, repeat,
                          keep_dir, ablate);
  const std::string robust_dir = data.shared + "/datasets/robust";
  std::vector<bench::RobustCase> cases = bench::sharedRobustCases(data.shared);
  std::vector<std::string> notes;
  if (cases.empty())
    notes.push_back("the shared robust files are absent (no NAME.g2o with NAME.labels in " +
                    robust_dir + ")");
  TemporaryDirectory temporary;
  if (!no_generated && !plan.bases.empty()) {
    const std::string out_dir = generatedDirectory(keep_dir, &temporary);
    std::vector<std::string> missing;
    const auto generated = bench::generateRobustCases(data.shared, plan, out_dir, &missing);
    cases.insert(cases.end(), generated.begin(), generated.end());
    for (const std::string& base : missing)
      notes.push_back("no generated files from " + base + ": " + data.shared + "/datasets/" + base +
                      ".g2o is absent");
  }
  if (cases.empty())
    throw std::runtime_error(
        "no robust files: none in " + robust_dir +
        (no_generated ? " (and --no-generated)"
                      : " and no base to generate from in " + data.shared + "/datasets"));
  cases = bench::selectCases(cases, data.only);
  if (cases.empty()) throw std::runtime_error("no robust file is named in --only " + data.only);
  const auto optimum = bench::readOptimumTable(data.shared);
  const auto anchors = bench::readRobustAnchorTable(data.shared);
  if (optimum.empty())
    notes.push_back(data.shared +
                    "/reference/optimum.tsv is absent: F* unknown (F_clean / F* "
                    "shows —)");
  if (anchors.empty())
    notes.push_back(data.shared +
                    "/reference/robust-anchors.tsv is absent: no GTSAM GNC or riSAM figures");
  for (const std::string& n : notes) std::cerr << "arbor bench robust: " << n << "\n";

  const std::string load_before = loadAverage();
  // The replay rows: the robust replay as `arbor replay --robust` runs it, and the clean replay
  // of each base (tools/bench/robust_replay_hooks.h).
  const bench::RobustReplayHooks hooks = bench::robustReplayHooks(settings.gnc.kernel, repeat);
  const auto rows = bench::runRobustBench(cases, optimum, anchors, settings, hooks, &std::cerr);
  std::cout
      << "Robust batch: GNC-" << toString(settings.gnc.kernel) << " over LM"
      << (settings.certify ? ", then the certifiable solver on its inlier set" : "")
      << " (as `arbor batch --robust" << (settings.certify ? " --solver rtr" : "")
      << (settings.start == bench::BatchStart::kOnline
              ? "`, its defaults), from the robust online replay, its rejected closures held out, "
                "c² its bound"
              : " --init file`), c² " + threshold + ", from the file's vertices")
      << ", odometry (|i − j| = 1) trusted. F_clean / F*: F over the "
         "base file's edges against optimum.tsv; ATE: RMS position error against the clean "
         "optimum after a rigid alignment; precision and recall of the rejected edges against "
         "the labels (pairs unordered); total: start and solve; GNC steps over all rounds. "
         "GTSAM GNC and riSAM from reference/robust-anchors.tsv. Generated files: "
      << (no_generated ? std::string("none (--no-generated)")
                       : "from " + generate_from + ", fractions " + fractions + ", policies " +
                             policies + ", seed " + std::to_string(plan.seed))
      << ". Load average " << load_before << " at the start, " << loadAverage()
      << " at the end.\n\n";
  for (const std::string& n : notes) std::cout << "Note: " << n << ".\n";
  if (!notes.empty()) std::cout << "\n";
  std::cout << bench::robustMarkdown(rows);
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
        << "usage: arbor bench NAME [options]   (arbor bench NAME --help: its flags, grouped; "
           "--help-all: every one)\n"
           "  batch       the batch solvers against Ceres on the shared datasets\n"
           "  replay      the incremental replay against GTSAM's iSAM2 rows\n"
           "  paper       every solver of the paper's tables (docs/paper.md)\n"
           "  growth      latency against graph size and factorisation cost\n"
           "  covariance  marginal covariances against ceres::Covariance\n"
           "  robust      robust batch and replay on graphs with false loop closures\n"
           "  tree        the Bayes tree's size on a whole graph\n"
           "  micro       arbor-microbench (--sizes=N,... --benchmark_filter=REGEX ...)\n";
    return args.empty() ? 2 : 0;
  }
  try {
    const std::vector<std::string> rest(args.begin() + 1, args.end());
    if (args[0] == "batch") return batch(rest, ARBOR_SHARED_DIR);
    if (args[0] == "replay") return replay(rest, ARBOR_SHARED_DIR);
    if (args[0] == "paper") return paper(rest, ARBOR_SHARED_DIR);
    if (args[0] == "growth") return growth(rest, ARBOR_SHARED_DIR);
    if (args[0] == "covariance") return covariance(rest, ARBOR_SHARED_DIR);
    if (args[0] == "tree") return tree(rest, ARBOR_SHARED_DIR);
    if (args[0] == "robust") return robust(rest, ARBOR_SHARED_DIR);
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
