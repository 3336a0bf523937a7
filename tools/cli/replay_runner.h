// Feeding a pose graph's edges to the incremental smoother one update at a time, as
// `arbor replay` and `arbor bench replay` do: edges in order of max(i, j), then file order;
// per-update latency; a final relinearise-all pass; batch LM from the incremental estimate.
#pragma once

#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "arbor_slam/bayestree/incremental_smoother.h"
#include "arbor_slam/bayestree/online_smoother.h"
#include "arbor_slam/core/batch_solver.h"
#include "arbor_slam/core/latency_summary.h"
#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/io/edge_choice_file.h"

namespace arbor::cli {

struct ReplaySettings {
  SmootherOptions smoother;
  bool per_pose = false;  ///< one update per new pose (all its edges) instead of per edge
  /// > 0: the first update takes the first this many edges (whole groups, mergeFirstGroups), a
  /// map loaded before the rest streams in; the latency summary is then of the updates after
  /// it, and first_update_s its time.
  int first_update_edges = 0;
  /// New poses start at the graph's poses (its VERTEX values: a saved map) instead of the pose
  /// their first edge comes from composed with it (OnlineSmoother::setInitialGuess).
  bool initial_from_file = false;
  bool finalize = true;  ///< relinearise everything at the end
  bool batch = true;     ///< run batch LM from the incremental estimate
  /// Online robust smoothing (bayestree/online_gnc.h); the batch LM then runs over the edges
  /// it kept.
  std::optional<RobustOptions> robust;
  /// Per-edge trust and kernel (io/edge_choice_file.h, `--edge-choices`); empty: the rules.
  EdgeChoices choices;
  /// Every pose's marginal covariance from the final smoother's Bayes tree (after the final
  /// pass): ReplayResult::covariances.
  bool covariances = false;
};

struct UpdateRow {
  int step = 0;
  int edges_so_far = 0;
  double latency_ms = 0;
  int cliques_reeliminated = 0;
  int variables_relinearized = 0;
  int cliques_updated = 0;       ///< cliques given a rank update instead of re-eliminated
  int cliques_solved = 0;        ///< cliques re-solved by back-substitution
  int cliques_deferred = 0;      ///< after it: cliques a solve budget left for later updates
  int batch_reeliminations = 0;  ///< 1: the whole graph re-eliminated (BatchSwitchOptions)
  /// --relinearize async: 1 when a relinearisation job (or its catch-up) ran during the update
  /// (in flight before and after it, or started by it), and when the update swapped one in
  int async_job_running = 0, async_swapped = 0;
  /// Where the update's time went (UpdateStats: swap_s, prepare_s, top_s, solve_s), ms, and
  /// the flops of the cliques it re-eliminated (UpdateStats::reelimination_flops), MFlop
  double swap_ms = 0, prepare_ms = 0, top_ms = 0, solve_ms = 0, reelimination_mflop = 0;
  long peak_rss_kb = 0;  ///< the process's peak RSS after the update (cli/peak_rss.h)
};

template <class G>
struct ReplayResult {
  std::vector<UpdateRow> rows;
  LatencySummary latency;
  TenthsSummary tenths;       ///< of the first and the last tenth of the updates (the load apart)
  double total_s = 0;         ///< updates + final relinearisation
  double update_s = 0;        ///< sum of update latencies
  double first_update_s = 0;  ///< with ReplaySettings::first_update_edges: that update's time
  double finalize_s = 0;      ///< the final relinearise-all pass
  /// The final pass's Gauss–Newton iterations over everything (each relinearises all and
  /// re-eliminates the whole tree; with --robust, summed over finalize()'s rounds).
  int finalize_iterations = 0;
  double F_incremental = 0;  ///< before the final pass
  /// --solve-budget-mb: the cliques still deferred after the last update, and F once they are
  /// solved (before the final pass; F_incremental when none is)
  int deferred_at_end = 0;
  double F_drained = 0;
  double F_final = 0;
  BatchSummary batch;  ///< LM from the final estimate (if settings.batch)
  int relinearized = 0, indeterminate = 0, duplicates = 0, rejected = 0, pending = 0;
  std::vector<std::string> rejections;  ///< one line per rejected edge
  std::vector<G> poses;                 ///< the final estimate in the graph's dense order
  std::vector<G> batch_poses;           ///< the batch LM estimate
  OnlineStats online;                   ///< the online layer's counts at the end
  std::vector<ClosureReport> closures;  ///< with settings.robust: every loop closure
  /// With settings.covariances: each known pose's marginal covariance (of the final smoother's
  /// linear system; zero for an anchor), of id covariance_ids[k].
  std::vector<Key> covariance_ids;
  std::vector<Eigen::Matrix<double, G::kDoF, G::kDoF>> covariances;
};

/// The graph's edges the robust replay kept: false for an edge whose (from, to) ids a rejected
/// closure has (`closures`' outliers).
template <class G>
std::vector<char> keptEdges(const PoseGraph<G>& graph, const std::vector<ClosureReport>& closures);

template <class G>
ReplayResult<G> runReplay(const PoseGraph<G>& graph, const ReplaySettings& settings);

/// What a replay runs between updates, on the replay thread (both optional).
template <class G>
struct ReplayHooks {
  /// After each update, with the row just recorded (a hook may add to its latency).
  std::function<void(OnlineSmoother<G>&, UpdateRow&)> after_update;
  /// After the last update, before the final relinearise-all pass.
  std::function<void(OnlineSmoother<G>&)> after_stream;
};

/// The replay of runReplay without its batch LM: feeds `graph` into `smoother` (one update per
/// edge or per pose), runs the final pass (settings.finalize) and fills everything of the result
/// but `batch` and `batch_poses`. `smoother` keeps the final state for the caller.
template <class G>
ReplayResult<G> replayInto(const PoseGraph<G>& graph, const ReplaySettings& settings,
                           OnlineSmoother<G>& smoother, const ReplayHooks<G>& hooks = {});

/// Writes `rows` as CSV (step, edges, latency_ms, cliques_reeliminated, variables_relinearized,
/// cliques_updated, cliques_solved, async_job_running, async_swapped, the phase times,
/// reelimination_mflop, cliques_deferred).
void writeLatencyCsv(const std::string& path, const std::vector<UpdateRow>& rows);

}  // namespace arbor::cli
