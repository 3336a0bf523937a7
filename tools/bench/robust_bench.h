// `arbor bench robust` (issue 14, part 7): the robust batch (GNC over LM, as `arbor batch
// --robust` runs it) on graphs with planted false loop closures, each estimate judged against
// its base file and its labels (tools/bench/robust_metrics.h), beside the reference figures of
// GTSAM's GNC and riSAM (reference/robust-anchors.tsv).
//
// The files: the shared ones (DIR/datasets/robust/NAME.g2o with NAME.labels beside; the base
// DIR/datasets/BASE.g2o, BASE the part of NAME before "_random_", "_local_" or "_group_") and
// the bench's own, generated into a temporary directory from shared clean sets as `arbor
// generate outliers --input DIR/datasets/BASE.g2o --outliers F --outlier-policy P --seed S`
// does (tools/generator/false_closures.h), named BASE_P_F_seedS.
//
// The families of generated worlds (issue 52's held-out protocol, tools/bench/world_families.h):
// each world of a family × dimension × seed is generated into the same temporary directory
// (NAME.g2o, NAME = "vehicle-2d-s1"), its false closures planted with the world's seed
// (NAME_P_F.g2o and .labels); the world is the base, and its F* is the clean optimum the bench
// computes (below), there being no optimum.tsv row for it.
//
// The clean optimum (the ATE's reference) is computed once per base: LM from the base file's
// vertices (the odometry chain without them); when that ends more than 0.1% above F* (or F* is
// unknown) the certifiable solver (rtr: SE-Sync's staircase, then an LM polish) runs as well
// and the lower F is kept. The row says which and at what F.
//
// Replay rows: the extension point is RobustReplayHooks. A robust replay registered there
// (robust2/robust3) gets the same judgement as the batch (RobustRow::replay: F_clean, ATE,
// precision, recall, total and its per-update latency); a clean replay of the base file
// (clean2/clean3, once per base) gives the denominators of issue 14's cost goals (robust replay
// total ≤ 2× the clean replay's, p99 ≤ 3×). With no hook the table has no replay columns;
// `arbor bench robust` registers robust_replay_hooks.h's.
#pragma once

#include <functional>
#include <iosfwd>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "arbor_slam/core/gnc_solver.h"
#include "arbor_slam/core/latency_summary.h"
#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/io/labels_file.h"
#include "arbor_slam/tools/bench/robust_metrics.h"
#include "arbor_slam/tools/bench/shared_data.h"
#include "arbor_slam/tools/generator/false_closures.h"

namespace arbor::bench {

/// One file of the benchmark.
struct RobustCase {
  std::string name;       ///< "M3500_group_0.1" (shared) or "intel_group_0.5_seed1" (generated)
  std::string file;       ///< the graph with the false closures
  std::string labels;     ///< its labels (io/labels_file.h)
  std::string base;       ///< the base dataset's name, "M3500"
  std::string base_file;  ///< DIR/datasets/BASE.g2o
  std::string policy;     ///< random | local | group
  double fraction = std::numeric_limits<double>::quiet_NaN();  ///< of the base's loop closures
  bool generated = false;
  std::string family;  ///< a generated world's family ("vehicle"); empty for the others
  /// a family world's X (Ω written = X · the drawn noise's information); NaN for the others
  double information_scale = std::numeric_limits<double>::quiet_NaN();
};

/// The shared robust files (header comment), smallest first; empty when DIR/datasets/robust
/// is absent. A .g2o without its .labels, or whose name has no policy, is left out.
std::vector<RobustCase> sharedRobustCases(const std::string& shared_dir);

/// What the bench generates: every base × fraction × policy, one seed.
struct GenerationPlan {
  std::vector<std::string> bases = {"intel", "smallGrid3D"};  ///< a 2D and a 3D shared set
  std::vector<double> fractions = {0.1, 0.5, 0.9};            ///< of the base's loop closures
  std::vector<sim::OutlierPolicy> policies = {
      sim::OutlierPolicy::kRandom, sim::OutlierPolicy::kLocal, sim::OutlierPolicy::kGroup};
  std::uint64_t seed = 1;
};

/// Writes BASE_P_F_seedS.g2o and .labels into `out_dir` for each case of `plan` and returns
/// them. A base whose file is absent is skipped and its name appended to *missing. Throws
/// std::invalid_argument (from the generator) when a case cannot be planted, FileError when a
/// file cannot be read or written.
std::vector<RobustCase> generateRobustCases(const std::string& shared_dir,
                                            const GenerationPlan& plan, const std::string& out_dir,
                                            std::vector<std::string>* missing);

/// Plants round(f · L) false closures with `seed` into `graph` for each fraction f × policy,
/// writes each as OUT_DIR/NAME.g2o and NAME.labels, NAME = `like.base` + "_" + policy + "_" + f +
/// `suffix`, and returns the cases, each a copy of `like` (base, base_file, family, ...) with
/// its name, files, policy and fraction. A graph without vertices is written with its odometry
/// chain (as `arbor generate outliers`). Throws std::invalid_argument (from the generator) when
/// a case cannot be planted, FileError when a file cannot be written.
template <class G>
std::vector<RobustCase> plantRobustCases(PoseGraph<G> graph, const RobustCase& like,
                                         const std::vector<double>& fractions,
                                         const std::vector<sim::OutlierPolicy>& policies,
                                         std::uint64_t seed, const std::string& out_dir,
                                         const std::string& suffix);

/// The cases named in the comma-separated `only` (a case's name, or a base's name for all of
/// its cases); all of them when `only` is empty.
std::vector<RobustCase> selectCases(const std::vector<RobustCase>& cases, const std::string& only);

/// What a robust method returned on a graph.
template <class G>
struct RobustEstimate {
  std::vector<G> poses;                   ///< one per pose of the graph, its dense order
  std::vector<char> rejected;             ///< one per edge: classified a false closure
  double total_s = 0;                     ///< the whole run, its start included
  int steps = 0;                          ///< batch: GNC steps over all rounds; replay: updates
  std::optional<LatencySummary> latency;  ///< replay: per-update latency
  std::string note;                       ///< e.g. "certified", a stop message
};

/// An estimate judged (robust_metrics.h).
struct RobustFigures {
  bool ok = false;
  std::string error;                                          ///< why the method failed (ok false)
  double F_clean = std::numeric_limits<double>::quiet_NaN();  ///< over the base file's edges
  double F_ratio = std::numeric_limits<double>::quiet_NaN();  ///< F_clean / F* (NaN: no F*)
  double ate = std::numeric_limits<double>::quiet_NaN();      ///< against the clean optimum
  RejectionScore score;
  double total_s = std::numeric_limits<double>::quiet_NaN();
  int steps = 0;
  std::optional<LatencySummary> latency;
  std::string note;
};

/// A clean replay of the base file, the denominator of the cost goals.
struct CleanReplayFigures {
  double total_s = std::numeric_limits<double>::quiet_NaN();
  LatencySummary latency;
};

/// The extension point for replay rows (header comment). Each hook runs its method on the graph
/// given; an empty hook is skipped; a hook that throws gives a failed figure with its message.
struct RobustReplayHooks {
  std::function<RobustEstimate<SE2>(const PoseGraph2&)> robust2;
  std::function<RobustEstimate<SE3>(const PoseGraph3&)> robust3;
  std::function<CleanReplayFigures(const PoseGraph2&)> clean2;  ///< called with the base graph
  std::function<CleanReplayFigures(const PoseGraph3&)> clean3;
};

/// One row of reference/robust-anchors.tsv (header of that file).
struct RobustAnchor {
  double total_s = 0, p50_ms = 0, p99_ms = 0, max_ms = 0;
  int rejected = 0;
  std::string status;  ///< "ok", "timeout(300s)", ...
  double F_clean = std::numeric_limits<double>::quiet_NaN();
  double F_ratio = std::numeric_limits<double>::quiet_NaN();
  double ate = std::numeric_limits<double>::quiet_NaN();
  double precision = std::numeric_limits<double>::quiet_NaN();
  double recall = std::numeric_limits<double>::quiet_NaN();
};

/// DIR/reference/robust-anchors.tsv keyed by (dataset, tool), tool "gnc", "risam", ...; empty
/// if absent.
std::map<std::pair<std::string, std::string>, RobustAnchor> readRobustAnchorTable(
    const std::string& shared_dir);

/// Where the robust batch starts (`arbor bench robust --batch-start`).
enum class BatchStart {
  kFile,    ///< the file's vertices, GNC at the given c² (`arbor batch --robust --init file`)
  kOnline,  ///< the robust online replay, its classification and threshold kept (`arbor batch
            ///< --robust`'s defaults; cli::solveGncFromReplay)
};

/// The robust batch, as `arbor batch --robust` runs it.
struct RobustBatchSettings {
  GncOptions gnc;        ///< --kernel, --inlier-threshold (outer LM: 100 iterations, 1e-5)
  bool certify = false;  ///< --solver rtr: then certifyInliers on GNC's inlier set
  BatchStart start = BatchStart::kOnline;
};

/// Starts from the file's vertices (the odometry chain without them) and runs solveGnc, or with
/// BatchStart::kOnline cli::solveGncFromReplay (its time included); with `certify` then
/// certifyInliers; rejected = the edges neither trusted nor inliers.
template <class G>
RobustEstimate<G> robustBatch(const PoseGraph<G>& graph, const RobustBatchSettings& settings);

/// The clean optimum of a base graph (header comment).
template <class G>
struct CleanReference {
  PoseGraph<G> base;
  std::vector<G> optimum;
  double F = std::numeric_limits<double>::quiet_NaN();       ///< at `optimum`
  double F_star = std::numeric_limits<double>::quiet_NaN();  ///< optimum.tsv
  std::string method;                                        ///< "lm" or "rtr"
};

template <class G>
CleanReference<G> cleanReference(PoseGraph<G> base, double F_star);

/// Judges `estimate` of `graph` against the base (F over its edges, ATE against its optimum)
/// and the labels. A malformed estimate (sizes) gives a failed figure saying so.
template <class G>
RobustFigures judgeEstimate(const PoseGraph<G>& graph, const RobustEstimate<G>& estimate,
                            const std::vector<LabelPair>& labels, const CleanReference<G>& ref);

/// One file's figures.
struct RobustRow {
  RobustCase c;
  int dim = 0, poses = 0, edges = 0;
  int loop_closures = 0;  ///< the base's (|i − j| > 1)
  int false_edges = 0;    ///< labels
  double F_star = std::numeric_limits<double>::quiet_NaN();
  double F_reference = std::numeric_limits<double>::quiet_NaN();  ///< the clean optimum's F
  /// the median χ² (eᵀΩe) of the base's loop closures at the clean optimum; NaN without any
  double closure_chi2_median = std::numeric_limits<double>::quiet_NaN();
  double closure_chi2_max = std::numeric_limits<double>::quiet_NaN();  ///< and the largest
  std::string reference_method;
  std::string error;  ///< the file, its labels or its base could not be used
  RobustFigures batch;
  std::optional<RobustFigures> replay;             ///< RobustReplayHooks::robust*
  std::optional<CleanReplayFigures> clean_replay;  ///< RobustReplayHooks::clean*
  /// robust-anchors.tsv (tools gnc, risam, isam2_cauchy; shared files only)
  std::optional<RobustAnchor> gnc, risam, isam2_cauchy;
};

/// Runs every case in turn (the references computed once per base), one line per case on
/// *progress when given. Never throws for one case: its row carries the error.
std::vector<RobustRow> runRobustBench(
    const std::vector<RobustCase>& cases, const std::map<std::string, Reference>& optimum,
    const std::map<std::pair<std::string, std::string>, RobustAnchor>& anchors,
    const RobustBatchSettings& settings, const RobustReplayHooks& hooks, std::ostream* progress);

/// Where the rows stand against issue 14's goals, one Markdown bullet each: quality (F_clean
/// within 1% of F*, precision and recall ≥ 0.95) for the replay and for the batch, on the rows
/// the goal covers (10% and 50% false closures, every policy; 90% random in 2D), and cost (the
/// replay's total ≤ 2× and p99 ≤ 3× the clean replay's) on every row with both replays; each
/// with the rows that miss it and their figures. Empty when no row has figures.
std::string robustGoals(const std::vector<RobustRow>& rows);

/// The rows as one Markdown table (replay columns when any row has them), then notes: each
/// base's clean optimum, each failure, and robustGoals.
std::string robustMarkdown(const std::vector<RobustRow>& rows);

/// Solved (issue 52): F over the base's edges within 1% of F* and precision and recall of the
/// rejected edges ≥ 0.95.
bool solved(const RobustFigures& f);

}  // namespace arbor::bench
