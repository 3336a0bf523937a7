// What the smoother's Bayes tree holds on a whole graph in a fresh ordering (`arbor bench
// tree`): symbolic only (the ordering and bayestree::planElimination, no numeric work), so it
// sizes graphs far beyond what a replay reaches, e.g. a 1,000,000-pose world in seconds. The
// tree is the one a batch re-elimination (BatchSwitchOptions) of that graph makes; the
// incremental tree between re-orderings holds up to `reorder_decay` times more.
#pragma once

#include <ostream>
#include <string>
#include <vector>

#include "arbor_slam/bayestree/tree_shape.h"
#include "arbor_slam/core/latency_summary.h"
#include "arbor_slam/core/pose_graph.h"

namespace arbor::bench {

struct TreeSizeRow {
  std::string ordering;   ///< "colamd" or "nested dissection"
  double ordering_s = 0;  ///< the ordering and the symbolic elimination, wall
  double max_ratio = 0;   ///< CachedFactorOptions::max_ratio
  bayestree::TreeShape shape;
};

/// The rows as a markdown table; `poses` for the per-pose column.
void printTreeSizeTable(std::ostream& out, const std::vector<TreeSizeRow>& rows, int poses);

/// What the last tenth of `graph`'s edges (file order, the updates of an edge-by-edge replay's
/// last tenth) cost an exact smoother at least, in the tree of the whole graph under one
/// ordering (bayestree::pathCost): a floor on their latency, not a measurement of it. Odometry
/// edges (|i − j| = 1 in dense indices) count as free: an incremental ordering keeps the newest
/// poses at the root (the constrained ordering of iSAM2), where the edge touches one clique.
/// A loop closure's cost is its path's in the fresh tree, whose separators an incremental tree
/// only matches right after a re-ordering.
struct PathCostRow {
  std::string ordering;  ///< as TreeSizeRow
  int updates = 0;       ///< edges in the last tenth
  int closures = 0;      ///< of them loop closures
  /// Over the loop closures: percentiles (nearest rank, summarizeLatency, here of counts,
  /// MFlop and MB of 8-byte doubles) of the cliques reached and of each estimate.
  LatencySummary cliques, reelimination_mflop, rank_update_mflop, rewritten_mb;
  /// Over every update of the last tenth (odometry free): the same estimates, whose p99 is the
  /// floor the updates' p99 latency stands on.
  LatencySummary updates_reelimination_mflop, updates_rank_update_mflop, updates_rewritten_mb;
};

/// Both tables of one graph, each ordering computed once.
struct TreeReport {
  std::vector<TreeSizeRow> sizes;
  std::vector<PathCostRow> paths;
};

/// For each ordering (CCOLAMD, as the smoother orders 2D tops; CHOLMOD's nested dissection, as
/// it orders 3D tops of 100 poses or more): the shape of the tree of every variable of `graph`
/// (its gauge poses fixed), unconstrained, at each ratio, and the last tenth's path costs in it.
template <class G>
TreeReport treeReport(const PoseGraph<G>& graph, const std::vector<double>& ratios);

/// The rows as a markdown table.
void printPathCostTable(std::ostream& out, const std::vector<PathCostRow>& rows);

}  // namespace arbor::bench
