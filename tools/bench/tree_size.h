// What the smoother's Bayes tree holds on a whole graph in a fresh ordering (`arbor bench
// tree`): symbolic only (the ordering and bayestree::planElimination, no numeric work), so it
// sizes graphs far beyond what a replay reaches, e.g. a 1,000,000-pose world in seconds. The
// tree is the one a batch re-elimination (BatchSwitchOptions) of that graph makes; the
// incremental tree between re-orderings holds up to `reorder_decay` times more.
#pragma once

#include <ostream>
#include <string>
#include <vector>

#include "arbor/bayestree/tree_shape.h"
#include "arbor/core/pose_graph.h"

namespace arbor::bench {

struct TreeSizeRow {
  std::string ordering;   ///< "colamd" or "nested dissection"
  double ordering_s = 0;  ///< the ordering and the symbolic elimination, wall
  double max_ratio = 0;   ///< CachedFactorOptions::max_ratio
  bayestree::TreeShape shape;
};

/// For each ordering (CCOLAMD, as the smoother orders 2D tops; CHOLMOD's nested dissection, as
/// it orders 3D tops of 100 poses or more) and each ratio: the shape of the tree of every
/// variable of `graph` (its gauge poses fixed), unconstrained.
template <class G>
std::vector<TreeSizeRow> treeSizes(const PoseGraph<G>& graph, const std::vector<double>& ratios);

/// The rows as a markdown table; `poses` for the per-pose column.
void printTreeSizeTable(std::ostream& out, const std::vector<TreeSizeRow>& rows, int poses);

}  // namespace arbor::bench
