// A pose graph: poses (indexed densely 0..n−1, each with its external id), relative-pose edges
// between them, priors on single poses (core/prior_factors.h) and factors of your own on one or
// two poses (core/custom_factor.h). The gauge: the poses marked fixed; when none are, the priors
// (and custom factors) anchor the graph, and a graph without them is anchored at its first pose
// (core/gauge.h gives every connected component its anchor).
#pragma once

#include <cstdint>
#include <unordered_map>
#include <vector>

#include "arbor_slam/core/custom_factor.h"
#include "arbor_slam/core/gauge.h"
#include "arbor_slam/core/prior_factors.h"
#include "arbor_slam/core/relative_pose_factor.h"

namespace arbor {

using Key = std::int64_t;  ///< a pose id as it appears in files and messages

template <class Group>
struct PoseGraph {
  using GroupType = Group;
  using Edge = RelativePoseEdge<Group>;

  std::vector<Key> ids;                             ///< dense index → external id, ascending
  std::unordered_map<Key, int> index;               ///< external id → dense index
  std::vector<Group> poses;                         ///< the estimate (or initial guess), one per id
  std::vector<Edge> edges;                          ///< in file order
  std::vector<PosePriorFactor<Group>> pose_priors;  ///< in file order
  std::vector<PositionPriorFactor<Group>> position_priors;  ///< in file order
  std::vector<CustomFactor<Group>> custom_factors;          ///< in the order added
  std::vector<int> fixed;             ///< dense indices held fixed (empty: the first pose)
  bool has_initial_estimate = false;  ///< poses came from the file's VERTEX lines

  int numPoses() const { return static_cast<int>(ids.size()); }
  int numEdges() const { return static_cast<int>(edges.size()); }
  int numPriors() const { return static_cast<int>(pose_priors.size() + position_priors.size()); }
  bool hasPriors() const { return numPriors() > 0; }
  int numCustomFactors() const { return static_cast<int>(custom_factors.size()); }

  /// The dense indices held fixed by the batch solvers: `fixed` when it is not empty, else the
  /// first pose of every connected component that its priors do not anchor (core/gauge.h): for a
  /// connected graph without priors its first pose; none when the priors anchor everything.
  /// Custom factors join components (binary ones) and anchor them as far as their gauge
  /// information at `poses` says (core/gauge.h). O(n + m).
  std::vector<int> gaugeIndices() const {
    if (!fixed.empty() || ids.empty()) return fixed;
    return anchorPoses<Group>(numPoses(), edges, pose_priors, position_priors, custom_factors,
                              poses);
  }
};

using PoseGraph2 = PoseGraph<SE2>;
using PoseGraph3 = PoseGraph<SE3>;

/// Σ eᵀΩe over the edges, priors and custom factors at `poses` (the objective F reported
/// everywhere).
template <class Group>
double objective(const PoseGraph<Group>& graph, const std::vector<Group>& poses) {
  double f = 0.0;
  for (const auto& e : graph.edges) f += e.cost(poses[e.i], poses[e.j]);
  for (const auto& p : graph.pose_priors) f += p.cost(poses[p.i]);
  for (const auto& p : graph.position_priors) f += p.cost(poses[p.i]);
  for (const auto& c : graph.custom_factors) f += c.cost(poses);
  return f;
}

}  // namespace arbor
