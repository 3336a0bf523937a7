// Test helper: a clean graph with false loop closures planted by sim::addFalseClosures (as
// `arbor generate outliers` plants them), and the planted closures' id pairs.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <set>
#include <utility>

#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/core/se2.h"
#include "arbor_slam/tools/generator/false_closures.h"
#include "arbor_slam/tools/generator/graph_generator.h"

namespace arbor::testing {

template <class G>
struct PlantedGraph {
  PoseGraph<G> clean;
  PoseGraph<G> graph;                      ///< clean with the false closures appended
  std::set<std::pair<Key, Key>> is_false;  ///< the false closures' (from, to) ids, low first
};

template <class G>
PlantedGraph<G> plantFalseClosures(PoseGraph<G> clean, const sim::OutlierOptions& options) {
  PlantedGraph<G> p;
  p.clean = std::move(clean);
  const sim::FalseClosures<G> planted = sim::addFalseClosures(p.clean, options);
  p.graph = planted.graph;
  for (const auto& [i, j] : planted.pairs) {
    const Key a = p.graph.ids[static_cast<size_t>(i)], b = p.graph.ids[static_cast<size_t>(j)];
    p.is_false.insert({std::min(a, b), std::max(a, b)});
  }
  return p;
}

/// `arbor generate manhattan --poses N --seed S`, then `arbor generate outliers --outliers F
/// --outlier-policy group --seed S`.
inline PlantedGraph<SE2> manhattanWithFalseGroups(int poses, std::uint64_t seed, double fraction) {
  sim::ManhattanOptions world;
  world.poses = poses;
  world.seed = seed;
  sim::OutlierOptions o;
  o.fraction = fraction;
  o.policy = sim::OutlierPolicy::kGroup;
  o.seed = seed;
  return plantFalseClosures(sim::manhattanWorld(world).graph, o);
}

}  // namespace arbor::testing
