// A pose graph: poses (indexed densely 0..n−1, each with its external id) and relative-pose
// edges between them. The first pose (or the poses marked fixed) fixes the gauge.
#pragma once

#include <cstdint>
#include <unordered_map>
#include <vector>

#include "core/relative_pose_factor.h"

namespace arbor {

using Key = std::int64_t;  ///< a pose id as it appears in files and messages

template <class Group>
struct PoseGraph {
  using GroupType = Group;
  using Edge = RelativePoseEdge<Group>;

  std::vector<Key> ids;                ///< dense index → external id, ascending
  std::unordered_map<Key, int> index;  ///< external id → dense index
  std::vector<Group> poses;            ///< the estimate (or initial guess), one per id
  std::vector<Edge> edges;             ///< in file order
  std::vector<int> fixed;              ///< dense indices held fixed (empty: the first pose)
  bool has_initial_estimate = false;   ///< poses came from the file's VERTEX lines

  int numPoses() const { return static_cast<int>(ids.size()); }
  int numEdges() const { return static_cast<int>(edges.size()); }

  /// The dense indices that fix the gauge: `fixed`, or the first pose when it is empty.
  std::vector<int> gaugeIndices() const {
    if (!fixed.empty() || ids.empty()) return fixed;
    return {0};
  }
};

using PoseGraph2 = PoseGraph<SE2>;
using PoseGraph3 = PoseGraph<SE3>;

/// Σ eᵢⱼᵀ Ωᵢⱼ eᵢⱼ over the edges at `poses` (the objective F reported everywhere).
template <class Group>
double objective(const PoseGraph<Group>& graph, const std::vector<Group>& poses) {
  double f = 0.0;
  for (const auto& e : graph.edges) f += e.cost(poses[e.i], poses[e.j]);
  return f;
}

}  // namespace arbor
