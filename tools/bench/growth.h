// How the replay's latency grows with the graph, set against what one batch factorisation of
// the graph so far costs (`arbor bench growth`). A relinearisation step that relinearises
// variables spread over the whole graph re-eliminates nearly every clique, so its cost cannot
// fall below a factorisation of the graph: this table shows whether the band of those steps
// follows that cost, and how much of the graph each step relinearised.
#pragma once

#include <ostream>
#include <string>
#include <vector>

#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/tools/cli/replay_runner.h"

namespace arbor::bench {

/// The updates of one slice of a replay (those after which the graph had more than the
/// previous slice's poses and at most `poses`).
struct GrowthSlice {
  int poses = 0;  ///< poses known after the slice's last update
  int edges = 0;  ///< edges fed so far
  /// Flops of one sparse Cholesky factorisation of the Gauss–Newton system of the graph so far
  /// (the poses 0..poses−1 and the edges among them, gauge the first pose), in the best of
  /// AMD, METIS and CHOLMOD's nested dissection (NormalEquations); 0 when not computable.
  double factorization_flops = 0;
  /// Time of that numeric factorisation at the graph's initial poses, on one thread
  /// (NormalEquations::factorize, the fastest of three runs) with BlockCholesky and with
  /// CHOLMOD, and the faster of the two; 0 when H is not positive definite there.
  double block_ms = 0, cholmod_ms = 0, factorization_ms = 0;
  /// Time of NormalEquations::linearize at those poses with the faster back-end (every
  /// factor's error and Jacobians, and H's blocks), on one thread, the fastest of three runs:
  /// what an update that relinearises every variable adds to a factorisation at least (its
  /// factors must be linearised again); 0 when not timed.
  double linearization_ms = 0;
  int relin_updates = 0;    ///< updates that relinearised at least one variable
  double relin_p50_ms = 0;  ///< their median latency
  double relin_max_ms = 0;  ///< and their largest
  double relin_share = 0;   ///< their mean variables relinearised / poses known
  int other_updates = 0;    ///< the rest
  double other_p50_ms = 0, other_p99_ms = 0;
  double max_ms = 0;     ///< the slice's largest update of any kind
  int largest_step = 0;  ///< its UpdateRow::step
  /// What it was (updateKind): swap, batch, relinearisation, top (more than two cliques
  /// re-eliminated), fold-in (rank updates only), or other (at most two cliques).
  std::string largest_kind;
  int batch_updates = 0;  ///< updates that re-eliminated the whole graph (BatchSwitchOptions)
  /// The process's peak RSS after the slice's last update (getrusage, = VmHWM): the smoother,
  /// the loaded graph and the process's baseline; and it per pose known.
  double peak_rss_mb = 0, rss_per_pose_kb = 0;
};

/// What an update did, by its row's counts, first match: "swap" (an async swap), "batch" (the
/// whole graph re-eliminated), "relinearisation", "top" (more than two cliques re-eliminated,
/// nothing relinearised: a loop closure's path), "fold-in" (rank updates only), "other" (new
/// poses and edges within at most two cliques).
std::string updateKind(const cli::UpdateRow& row);

/// Splits `replay` (one row per update of cli::replayGroups(graph, per_pose), as replayInto
/// returns it) into `slices` slices of equal pose count and measures each. Throws
/// std::invalid_argument when the rows do not match the graph's groups or slices < 1.
template <class G>
std::vector<GrowthSlice> growthSlices(const PoseGraph<G>& graph, const cli::ReplayResult<G>& replay,
                                      bool per_pose, int slices);

/// The slices as a markdown table (one row per slice; "relin. / factorisation" = relin_p50_ms
/// over factorization_ms; both backends' times are shown), with issue 17's two bounds: the
/// largest update (max_ms) over factorization_ms (at most 1.5) and other_p99_ms over it (at
/// most 0.25), judged in the slices whose factorisation takes at least 1 ms. Beside them,
/// linearization_ms and the batch's own "linearise + factorise" over factorization_ms: where
/// that is above 1.5, no update that relinearises every factor can meet the first bound.
void printGrowthTable(std::ostream& out, const std::vector<GrowthSlice>& slices);

}  // namespace arbor::bench
