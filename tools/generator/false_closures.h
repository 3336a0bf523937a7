// False loop closures appended to a pose graph, for testing robustness to outliers, after
// Sünderhauf & Protzel, "Switchable Constraints for Robust Pose Graph SLAM" (IROS 2012), and as
// the shared robust datasets were made (shared/datasets/robust/README.md):
//
//   count  N = round_half_even(fraction · L), L the graph's loop closures (edges with
//          |i − j| > 1, dense indices, i.e. ids in ascending order). Half to even is what the
//          shared files show: intel 0.1 · 785 = 78.5 → 78, 0.9 · 785 = 706.5 → 706, garage
//          0.1 · 4615 = 461.5 → 462 (M3500 0.1 · 1954 = 195.4 → 195).
//   pairs  (i, j), i < j, |i − j| > 1, never a pair that already holds an edge (either
//          direction) nor one drawn before, so that `i j` names one edge:
//          · random: i, j uniform over the poses;
//          · local:  d uniform in [local_min, local_max] (10–50), then i uniform in [0, n − d),
//                    j = i + d;
//          · group:  groups of group_size (10) consecutive pairs (i₀ + k, j₀ + k), k < g,
//                    i₀, j₀ drawn as for random among the starts that fit; the last group is
//                    cut to the count (195 = 19 groups of 10 and one of 5).
//   z      a random pose: each translation component uniform in [−h, h],
//          h = 3 · max(1, largest |translation component| of a real loop closure) (the
//          shared files: M3500 3 · 4.05 bounds its false closures at 12.15; torus3D, whose
//          closures are under 1 m, at 3), rotation uniform (SO(2): θ uniform in [−π, π);
//          SO(3): Shoemake's uniform unit quaternion, w ≥ 0).
//          A group shares one z: every pair of the group claims the same relative pose
//          xᵢ₀₊ₖ⁻¹ xⱼ₀₊ₖ = z, so the group agrees with itself (one rigid offset of the run
//          j₀… against the run i₀…; exactly satisfiable with the odometry when the runs'
//          steps satisfy oⱼ₀₊ₖ = z⁻¹ oᵢ₀₊ₖ z, as for two straight runs when z does not turn),
//          the hard case for a robust back end.
//   Ω      a copy of the information of a real loop closure drawn uniformly, for each false
//          edge (members of a group included).
//
// The false edges are appended after the graph's edges, in the order drawn; poses, priors and
// the fixed set are unchanged. Deterministic for a seed (tools/generator/random.h; the seed is
// mixed by one SplitMix64 step, so the outliers of `generate --seed S` do not reuse the graph's
// own stream).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/tools/generator/random.h"

namespace arbor::sim {

enum class OutlierPolicy { kRandom, kLocal, kGroup };

/// "random", "local", "group".
const char* toString(OutlierPolicy policy);
/// The inverse of toString; nullopt for anything else.
std::optional<OutlierPolicy> parseOutlierPolicy(const std::string& name);

struct OutlierOptions {
  double fraction = 0.1;  ///< false closures per real loop closure, finite, ≥ 0
  OutlierPolicy policy = OutlierPolicy::kRandom;
  std::uint64_t seed = 1;
  int group_size = 10;  ///< group: consecutive pairs sharing one z, ≥ 1
  int local_min = 10;  ///< local: |i − j| in [local_min, local_max], 2 ≤ local_min ≤ local_max
  int local_max = 50;
};

template <class Group>
struct FalseClosures {
  PoseGraph<Group> graph;  ///< the input with the false edges appended
  int first_false = 0;     ///< graph.edges[first_false …] are the false edges (the input's count)
  /// The false edges' pose pairs (dense indices, i < j), in the order appended.
  std::vector<std::pair<int, int>> pairs;
};

/// Edges with |i − j| > 1.
template <class Group>
int countLoopClosures(const PoseGraph<Group>& graph);

/// round_half_even(fraction · loop_closures); std::invalid_argument if fraction is negative or
/// not finite, or the count does not fit an int.
int falseClosureCount(double fraction, int loop_closures);

/// Appends the false closures. Throws std::invalid_argument naming the value for bad options
/// (fraction < 0 or not finite, fewer than two poses, a local window or a group the graph
/// cannot hold, more false closures than free pose pairs), std::runtime_error if the pairs
/// cannot be placed after many draws (nearly every free pair taken).
template <class Group>
FalseClosures<Group> addFalseClosures(const PoseGraph<Group>& graph, const OutlierOptions& options);

/// A random pose: translation components uniform in [−h, h], rotation uniform.
template <class Group>
Group randomPose(Random& rng, double half_width);
template <>
SE2 randomPose<SE2>(Random& rng, double half_width);
template <>
SE3 randomPose<SE3>(Random& rng, double half_width);

}  // namespace arbor::sim
