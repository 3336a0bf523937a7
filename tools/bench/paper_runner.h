// `arbor bench paper`: every solver of Arbor on one pose graph with the settings of Jurić,
// Kendeš, Marković, Petrović, "A Comparison of Graph Optimization Approaches for Pose Estimation
// in SLAM" (MIPRO 2021), Table II: at most 100 iterations, LM stopping at a relative decrease of
// F below 1e-5, RTR at a gradient norm below 1e-2. Solvers outside Arbor (the Ceres baseline,
// linked into arbor-bench only) come in as ExternalSolver callbacks, so this part needs no Ceres.
#pragma once

#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "arbor_slam/core/latency_summary.h"
#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/tools/cli/replay_runner.h"

namespace arbor::bench {

/// One solver's run on one dataset.
struct SolverRun {
  std::string solver;  ///< "replay", "lm", "gn", "dogleg", "rtr", "ceres", ...
  double time_s = 0;   ///< the solve alone (initialisation and problem set-up excluded)
  double F = std::numeric_limits<double>::quiet_NaN();  ///< Σ eᵀΩe at its estimate
  int iterations = 0;  ///< iterations (replay: updates; rtr: trust-region iterations)
  /// converged | max_iterations | failed | certified (rtr) | complete (replay)
  std::string termination;
  std::string note;           ///< e.g. why it failed, or "relaxation not exact"
  std::string estimate_file;  ///< the CSV written (empty if none)
};

/// A solver from outside Arbor: called with the graph and the shared spanning-tree start in
/// *poses, leaves its estimate there and returns its run (F is recomputed by the caller).
struct ExternalSolver {
  std::string name;
  std::function<SolverRun(const PoseGraph2&, std::vector<SE2>*)> solve2;
  std::function<SolverRun(const PoseGraph3&, std::vector<SE3>*)> solve3;
};

struct PaperSettings {
  int max_iterations = 100;              ///< LM, GN, dogleg (the paper: 100)
  double relative_tolerance = 1e-5;      ///< LM, GN, dogleg (the paper's LM: 1e-5)
  double rtr_gradient_tolerance = 1e-2;  ///< RTR (the paper's SE-Sync: 1e-2)
  bool replay = true;                    ///< run the incremental replay
  std::string out_dir;  ///< write OUT_DIR/estimates/NAME/SOLVER.csv and OUT_DIR/latency/NAME.csv
};

struct DatasetReport {
  std::string name, note;
  int dim = 0, poses = 0, edges = 0;
  double F_star = std::numeric_limits<double>::quiet_NaN();  ///< optimum.tsv; NaN if absent
  std::vector<SolverRun> runs;                               ///< in the order they ran
  LatencySummary latency;                                    ///< replay's per-update latency
  std::string latency_file;                                  ///< replay's latency CSV
};

/// Runs replay (cli::runReplay, smoother defaults, final pass, no trailing LM), every batch
/// solver of refine::batchSolvers() in its order (LM, GN, dogleg from a breadth-first spanning
/// tree; RTR: SE-Sync's staircase from its chordal start, then LM polish, as `arbor batch
/// --solver rtr`) and each `external` solver (from the same spanning tree) on `graph`. A solver
/// that throws is reported as failed with the message; the others still run. Throws
/// std::runtime_error if out_dir is given and a file cannot be written.
template <class G>
DatasetReport runPaperBenchmark(const std::string& name, const PoseGraph<G>& graph,
                                const PaperSettings& settings,
                                const std::vector<ExternalSolver>& external = {});

/// Writes `poses` as CSV: a header "x,y" (2D) or "x,y,z" (3D), one row per pose (dense order).
template <class G>
void writeEstimateCsv(const std::string& path, const std::vector<G>& poses);

/// Tab-separated results, one row per (dataset, solver); a header line first.
void writeResultsTsv(const std::string& path, const std::vector<DatasetReport>& reports);
/// The same as one JSON array of datasets.
void writeResultsJson(const std::string& path, const std::vector<DatasetReport>& reports);
/// A Markdown section: the Table II-shaped table (time, F, termination per solver), F against
/// F*, time ratios to `baseline` (a solver name; skipped if no dataset ran it) and the replay
/// latency table.
std::string paperMarkdown(const std::vector<DatasetReport>& reports,
                          const std::string& baseline = "ceres");

}  // namespace arbor::bench
